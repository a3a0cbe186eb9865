"""Variant storage and service on both engines: fingerprints, relations seen from both sides,
reviewers' decisions kept (also after a model is deleted), and nothing else touched."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.mesh import Mesh
from app.services import catalog, ingestion, variants
from app.services.context import open_context
from app.services.errors import InvalidInputError, NotFoundError
from app.storage import models as models_repo
from app.storage import variants as variants_repo
from tests.conftest import make_settings
from tests.pg_server import db_url, pg_admin_url  # noqa: F401 (fixtures)
from tests.variant_meshes import hull_trimesh


def _hull_bytes(scale: float = 1.0, seed: int = 5) -> tuple[bytes, Mesh]:
    tm = hull_trimesh(seed, scale=scale)
    return tm.export(file_type="stl"), Mesh(np.asarray(tm.vertices), np.asarray(tm.faces, np.int64))


def test_detect_links_both_ways_and_decisions_are_kept(db_url, tmp_path):  # noqa: F811
    ctx = open_context(make_settings(tmp_path / "d", database_url=db_url))
    data_a, mesh_a = _hull_bytes()
    data_b, mesh_b = _hull_bytes(scale=25.4)
    data_c, mesh_c = _hull_bytes(seed=9)
    a = ingestion.submit(ctx, data_a, "a.stl").model.id
    b = ingestion.submit(ctx, data_b, "b.stl").model.id
    c = ingestion.submit(ctx, data_c, "c.stl").model.id
    assert variants.detect(ctx, a, mesh_a) == []  # nothing stored before it
    found = variants.detect(ctx, b, mesh_b)
    assert [(f["model_id"], f["relation"]) for f in found] == [(a, "rescaled")]
    assert variants.detect(ctx, c, mesh_c) == []  # another shape: no link

    from_b = variants.variants_of(ctx, b)
    assert len(from_b) == 1 and from_b[0]["scale"] == pytest.approx(1 / 25.4, rel=1e-6)  # b onto a
    from_a = variants.variants_of(ctx, a)  # the link was stored from b: seen from a, reversed
    assert from_a[0]["model_id"] == b and from_a[0]["relation"] == "rescaled"
    assert from_a[0]["scale"] == pytest.approx(25.4, rel=1e-6)
    t = np.asarray(from_a[0]["transform"])  # takes a's vertices onto b's
    moved = mesh_a.vertices @ t[:3, :3].T + t[:3, 3]
    gap = np.linalg.norm(moved[:, None] - mesh_b.vertices[None], axis=2).min(axis=1)
    assert gap.max() < 1e-4 * np.ptp(mesh_b.vertices, axis=0).max()
    assert variants.relations_with(ctx, a) == {b: "rescaled"}

    variants.decide(ctx, a, b, "not_variant", "different revisions")
    variants.decide(ctx, b, a, "keep_both", None)  # either order names the same pair; the latest wins
    assert variants.variants_of(ctx, a)[0]["decision"]["decision"] == "keep_both"
    from app.storage.variants import KEPT_DECISIONS

    for i in range(KEPT_DECISIONS + 2):  # a pair keeps its latest KEPT_DECISIONS, on either engine
        variants.decide(ctx, a, b, "keep_both", f"n{i}")
    with ctx.db.read() as conn:
        notes = [n for (n,) in conn.execute("SELECT note FROM variant_decisions ORDER BY seq").fetchall()]
    assert notes == [f"n{i}" for i in range(2, KEPT_DECISIONS + 2)]
    with pytest.raises(InvalidInputError):
        variants.decide(ctx, a, b, "merge", None)
    with pytest.raises(InvalidInputError):
        variants.decide(ctx, a, a, "keep_both", None)
    with pytest.raises(NotFoundError):
        variants.decide(ctx, a, 999, "keep_both", None)
    with ctx.db.read() as conn:
        assert models_repo.count_by_status(conn)["queued"] == 3  # decisions touch no model

    catalog.delete_model(ctx, None, b)  # a user's delete: the links go with the model ...
    assert variants.variants_of(ctx, a) == []
    with ctx.db.read() as conn:  # ... the reviewer's decisions stay on record
        assert variants_repo.decisions_of(conn, a)[b]["decision"] == "keep_both"
        ids, vectors, _ = variants_repo.fingerprints_since(conn, 0, 1, vectors_dim := 17)
    assert set(ids.tolist()) == {a, c} and vectors.shape[1] == vectors_dim


def test_a_candidate_every_fingerprint_pair_rules_out_is_not_read(tmp_path, monkeypatch):
    """A box found by the lookup for a torus (fingerprints within the radius) but ruled out by the
    gate's per-entry box for every pair of their fingerprints: no link, and its file is not read."""
    import trimesh

    from app.core.variants import Prepared
    from app.core.variants.gate import RADIUS

    ctx = open_context(make_settings(tmp_path / "d"))
    box = trimesh.creation.box(extents=[1, 2, 3]).subdivide().subdivide()
    torus = trimesh.creation.torus(1.0, 0.3, major_sections=48, minor_sections=24)
    meshes = [Mesh(np.asarray(t.vertices), np.asarray(t.faces, np.int64)) for t in (box, torus)]
    assert np.linalg.norm(Prepared(meshes[0]).fingerprint - Prepared(meshes[1]).fingerprint) <= RADIUS
    ids = [ingestion.submit(ctx, t.export(file_type="stl"), f"{n}.stl").model.id
           for n, t in (("box", box), ("torus", torus))]
    read: list[str] = []
    real = variants.stored_prepared
    monkeypatch.setattr(variants, "stored_prepared", lambda c, sha, ft: read.append(sha) or real(c, sha, ft))
    assert variants.detect(ctx, ids[0], meshes[0]) == []
    assert variants._cache(ctx).candidates(ctx, np.array([Prepared(meshes[1]).fingerprint]), None) == [ids[0]]
    assert variants.detect(ctx, ids[1], meshes[1]) == []
    assert read == []  # the box was a candidate, never read
    copy = ingestion.submit(ctx, box.export(file_type="obj").encode(), "box.obj").model.id
    assert [f["relation"] for f in variants.detect(ctx, copy, meshes[0])] == ["identical"]
    assert len(read) == 1  # a candidate the screen lets through is read and verified
