"""Backfill of fingerprints and links for models stored without them, and the cache of prepared
candidate meshes that spares an ingest re-reading them."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from app.cli import main
from app.core.mesh import Mesh
from app.services import ingestion, variants
from app.services.context import open_context
from app.storage import models as models_repo
from app.storage import variants as variants_repo
from tests.conftest import make_settings
from tests.pg_server import db_url, pg_admin_url  # noqa: F401 (fixtures)
from tests.variant_meshes import hull_trimesh


def _hull_bytes(scale: float = 1.0, seed: int = 5) -> bytes:
    return hull_trimesh(seed, scale=scale).export(file_type="stl")


def _stored_ready(ctx, data: bytes, name: str) -> int:
    """A model as an ingest before the variant step left it: ready, no fingerprint, no link."""
    model_id = ingestion.submit(ctx, data, name).model.id
    with ctx.db.write() as conn:
        models_repo.set_ready(conn, model_id, 42)
    return model_id


def _links(ctx, model_id: int) -> list[tuple[int, int, str]]:
    with ctx.db.read() as conn:
        return [(r["model_id"], r["other_id"], r["relation"]) for r in variants_repo.links_of(conn, model_id)]


def test_backfill_links_old_models_once_and_redoes_an_older_recipe(db_url, tmp_path):  # noqa: F811
    ctx = open_context(make_settings(tmp_path / "d", database_url=db_url))
    a = _stored_ready(ctx, _hull_bytes(), "a.stl")
    b = _stored_ready(ctx, _hull_bytes(scale=25.4), "b.stl")
    c = _stored_ready(ctx, _hull_bytes(seed=9), "c.stl")
    queued = ingestion.submit(ctx, _hull_bytes(scale=2.0), "queued.stl").model.id  # its job will do it

    seen: list[int] = []
    report = variants.backfill(ctx, lambda done, total, model_id: seen.append(model_id))
    assert (report["missing"], report["fingerprinted"], report["links"], report["skipped"]) == (3, 3, 1, [])
    assert seen == [a, b, c]  # oldest first: each later model finds the earlier ones
    assert _links(ctx, a) == [(b, a, "rescaled")]
    assert variants.variants_of(ctx, a)[0]["scale"] == pytest.approx(25.4, rel=1e-6)
    with ctx.db.read() as conn:
        ids, _, _ = variants_repo.fingerprints_since(conn, 0, variants.FINGERPRINT_VERSION, 17)
    assert set(ids.tolist()) == {a, b, c} and queued not in ids.tolist()

    again = variants.backfill(ctx)  # idempotent: nothing missing, nothing changed
    assert (again["missing"], again["fingerprinted"], again["links"]) == (0, 0, 0)
    assert _links(ctx, a) == [(b, a, "rescaled")]

    with ctx.db.write() as conn:  # a's fingerprints from an older recipe: a is done again
        conn.execute("UPDATE fingerprints SET version = ? WHERE model_id = ?",
                     (variants.FINGERPRINT_VERSION - 1, a))
    stale = variants.backfill(ctx)
    assert (stale["missing"], stale["fingerprinted"]) == (1, 1)
    assert {(x, y) for x, y, _ in _links(ctx, a)} in ({(b, a)}, {(b, a), (a, b)})


def test_backfill_command_reports_json(tmp_path, capsys):
    data_dir = tmp_path / "d"
    ctx = open_context(make_settings(data_dir))
    a = _stored_ready(ctx, _hull_bytes(), "a.stl")
    b = _stored_ready(ctx, _hull_bytes(scale=0.001), "b.stl")
    assert main(["variants", "backfill", "--data-dir", str(data_dir), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["missing"], report["fingerprinted"], report["links"]) == (2, 2, 1)
    assert _links(ctx, a) == [(b, a, "rescaled")]
    assert main(["variants", "backfill", "--data-dir", str(data_dir)]) == 0
    assert capsys.readouterr().out.startswith("0 models without fingerprints")
    assert main(["variants", "backfill", "--data-dir", str(tmp_path / "none")]) == 2  # no database there


def _sphere(subdivisions: int) -> Mesh:
    """42 vertices at 1 subdivision, 642 at 3."""
    tm = trimesh.creation.icosphere(subdivisions=subdivisions)
    return Mesh(np.asarray(tm.vertices), np.asarray(tm.faces, np.int64))


def test_prepared_cache_keeps_the_recent_within_its_bounds() -> None:
    loads: list[str] = []

    def loader(key: str, subdivisions: int = 1):
        return lambda: (loads.append(key), _sphere(subdivisions))[1]

    cache = variants.PreparedCache(max_models=2, max_vertices=10_000)
    first = cache.get(("a", "stl"), loader("a"))
    assert cache.get(("a", "stl"), loader("a")) is first  # read once, prepared once
    cache.get(("b", "stl"), loader("b"))
    cache.get(("a", "stl"), loader("a"))  # a is now the most recent
    cache.get(("c", "stl"), loader("c"))  # over two models: b, the least recent, goes
    assert loads == ["a", "b", "c"] and len(cache) == 2
    cache.get(("b", "stl"), loader("b"))
    assert loads[-1] == "b" and (cache.hits, cache.misses) == (2, 4)

    small = variants.PreparedCache(max_models=10, max_vertices=100)
    big = small.get(("big", "stl"), loader("big", 3))  # larger than the whole budget: used, not kept
    assert big.mesh.n_vertices == 642 and len(small) == 0
    for key in ("x", "y", "z"):
        small.get((key, "stl"), loader(key))  # 42 vertices each: two fit, x goes
    assert len(small) == 2
    small.get(("z", "stl"), loader("z"))
    small.get(("x", "stl"), loader("x"))
    assert loads[-4:] == ["x", "y", "z", "x"]


def test_reverse_says_which_one_lies_on_the_other() -> None:
    evidence = {"relation": "retriangulated", "forward": 1.0, "reverse": 0.9, "scale": 2.0,
                "transform": (2.0 * np.eye(4) + np.diag([0, 0, 0, -1.0])).tolist(), "lies_on_other": True}
    back = variants.reverse(evidence)
    assert back["lies_on_other"] is False and (back["forward"], back["reverse"]) == (0.9, 1.0)
    assert back["scale"] == 0.5 and variants.reverse(back)["lies_on_other"] is True
    assert variants.reverse({**evidence, "lies_on_other": None})["lies_on_other"] is None


def test_detect_keeps_the_new_model_prepared_for_the_next_ingests(tmp_path):
    ctx = open_context(make_settings(tmp_path / "d"))
    cache = variants.prepared_cache(ctx, variants.PreparedCache())
    a = _stored_ready(ctx, _hull_bytes(), "a.stl")
    b = _stored_ready(ctx, _hull_bytes(scale=25.4), "b.stl")
    report = variants.backfill(ctx)  # a's detect keeps a; b's meets a in the cache, never re-reads it
    assert (report["fingerprinted"], report["links"]) == (2, 1)
    assert (cache.hits, cache.misses, len(cache)) == (1, 0, 2)
    with ctx.db.read() as conn:
        stored = models_repo.get(conn, a)
    kept = cache.get((stored.sha256, stored.file_type), lambda: pytest.fail("re-read a kept model"))
    assert kept.mesh.n_vertices == hull_trimesh(5).vertices.shape[0]
    assert _links(ctx, a) == [(b, a, "rescaled")]
