"""POST /search with pieces: a half of a shape finds its whole first, with forward / reverse scores;
a whole query keeps the global ranking. Small generated meshes, through httpx (TestClient)."""

from __future__ import annotations

import csv
import functools
import tempfile
from pathlib import Path

import numpy as np
import pytest
import trimesh
from fastapi.testclient import TestClient

from app.config import DescribeSettings
from app.datasets.synthetic import generate
from app.main import create_app
from app.services import ingestion
from app.services import partial as partial_service
from app.services.context import open_context
from app.storage import jobs as jobs_repo
from app.worker.runner import Worker
from tests.conftest import make_settings

# the local signature's short times need the service's own resolution and eigenpairs (the other API
# tests' 40 eigenpairs at 300 vertices leave its first slopes to the triangulation)
DESCRIBE = DescribeSettings(k=300, m=20, target_vertices=1000)


def _shapes() -> dict[str, trimesh.Trimesh]:
    """Five synthetic articulated bodies (app.datasets.synthetic, one per plan) and a torus."""
    root = generate(_synthetic_dir(), classes=5, per_class=1, seed=0)
    with open(root / "labels.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    shapes = {row["class"]: trimesh.load(root / row["file"], process=False) for row in rows}
    shapes["torus"] = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=32,
                                             minor_sections=12)
    return shapes


@functools.cache
def _synthetic_dir() -> Path:
    return Path(tempfile.mkdtemp(prefix="partial-shapes-"))


def _half(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The faces on one side of a plane through the centre (not along a symmetry plane)."""
    normal = np.array([0.8, 0.5, 0.33])
    keep = (mesh.triangles_center - mesh.centroid) @ normal > 0
    return trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=True)


def _obj(mesh: trimesh.Trimesh) -> bytes:
    return trimesh.exchange.obj.export_obj(mesh).encode()


@pytest.fixture(scope="module")
def partial_dir(tmp_path_factory) -> tuple[Path, dict[str, int]]:
    data_dir = tmp_path_factory.mktemp("partial") / "data"
    ctx = open_context(make_settings(data_dir, describe=DESCRIBE))
    ids = {}
    for name, mesh in _shapes().items():
        ids[name] = ingestion.submit(ctx, _obj(mesh), f"{name}.obj", name=name, label=name).model.id
    describe_and_fit(ctx)
    return data_dir, ids


def describe_and_fit(ctx) -> None:
    """Run the queued ingests, then fit an 8-word vocabulary on them (the test settings ship none)."""
    worker = Worker(ctx, "seed")
    worker.run_forever(exit_when_idle=True)
    with ctx.db.write() as conn:
        jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={"size": 8})
    worker.run_forever(exit_when_idle=True)


def _search(client: TestClient, data: bytes, **fields: str) -> dict:
    r = client.post("/search", files={"file": ("q.obj", data)}, data={"k": "5", **fields})
    assert r.status_code == 200, r.text
    return r.json()


# the bodies whose halves the local signatures tell apart by a clear margin at this resolution (a half
# bird, snake or octopus comes within 10 % of another body's distance)
@pytest.mark.parametrize("name", ["quadruped", "biped"])
def test_a_half_finds_its_whole_first_with_scores(partial_dir, name):
    data_dir, ids = partial_dir
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        body = _search(client, _obj(_half(_shapes()[name])))
        hits = body["data"]
        assert hits[0]["model_id"] == ids[name]
        assert all(h["partial"] for h in hits)
        assert all(0.0 <= h["forward"] <= 1.0 and 0.0 <= h["reverse"] <= 1.0 for h in hits)
        # the piece is about half of its whole: the reverse score says so, within the grid's steps
        assert 0.3 <= hits[0]["reverse"] <= 0.8
        assert hits[0]["forward"] >= max(h["forward"] for h in hits[1:]) - 1e-9


def test_a_whole_query_keeps_the_global_ranking(partial_dir):
    data_dir, ids = partial_dir
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        data = _obj(_shapes()["torus"])
        auto = _search(client, data)["data"]
        forced_off = _search(client, data, partial="false")["data"]
        assert [h["model_id"] for h in auto] == [h["model_id"] for h in forced_off]
        assert not any(h["partial"] for h in auto)
        # the whole-shape order: the fusion re-rank's when it serves (the default), else the index's L1
        distances = [h["distance"] if h["rerank_distance"] is None else h["rerank_distance"] for h in auto]
        assert distances == sorted(distances)
        assert auto[0]["model_id"] == ids["torus"]
        assert auto[0]["forward"] == pytest.approx(1.0) and auto[0]["reverse"] == pytest.approx(1.0, abs=0.02)
        forced_on = _search(client, data, partial="true")["data"]
        assert all(h["partial"] for h in forced_on) and forced_on[0]["model_id"] == ids["torus"]


def test_a_bad_partial_option_is_a_clear_422(partial_dir):
    data_dir, _ = partial_dir
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        ball = _obj(_shapes()["snake"])
        r = client.post("/search", files={"file": ("q.obj", ball)}, data={"partial": "maybe"})
        assert r.status_code == 422 and "partial must be auto, true or false" in r.text


def test_the_coarse_pass_alone_finds_a_halfs_whole(partial_dir, monkeypatch):
    """With no global candidates, a piece's candidates are the coarse pass's nearest (a farthest-point
    eighth of its samples): the half still finds its whole first, and only those candidates come back."""
    data_dir, ids = partial_dir
    monkeypatch.setattr(partial_service, "GLOBAL_KEEP", 0)
    monkeypatch.setattr(partial_service, "COARSE_KEEP", 3)
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        hits = _search(client, _obj(_half(_shapes()["quadruped"])))["data"]
        assert len(hits) == 3 and hits[0]["model_id"] == ids["quadruped"]
        assert all(h["partial"] and h["forward"] is not None for h in hits)


def _canonical_vertices(mesh: trimesh.Trimesh) -> np.ndarray:
    """(n, 3) the vertices a stored model's description is of, in the mesh's own frame."""
    from app.core.mesh import load_mesh
    from app.core.pipeline import canonical_mesh

    return canonical_mesh(load_mesh(_obj(mesh), "obj"), DESCRIBE.params()).vertices


@pytest.mark.parametrize("name", ["quadruped", "biped"])
def test_a_pieces_hits_carry_the_region_it_matched_on_the_explained_mesh(partial_dir, name):
    """The region of the whole that the half matched: sample vertices of the mesh the explain view
    draws, weights summing to forward, and more of the weight on the side of the cut the half kept than
    that side's share of the samples."""
    data_dir, ids = partial_dir
    whole = _shapes()[name]
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        hits = _search(client, _obj(_half(whole)))["data"]
        first = hits[0]
        assert first["model_id"] == ids[name]
        for h in hits:
            region = h["region"]
            assert region is not None and 0 < len(region["vertices"]) == len(region["weights"]) <= 256
            assert sum(region["weights"]) == pytest.approx(h["forward"], abs=1e-3)
            assert min(region["weights"]) >= 0.0
        explained = client.get(f"/models/{ids[name]}/explain")
        assert explained.status_code == 200, explained.text
        n = len(explained.json()["shape"]["vertices"]) // 3
    vertices = first["region"]["vertices"]
    assert max(vertices) < n and len(set(vertices)) == len(vertices)
    canon = _canonical_vertices(whole)
    assert len(canon) == n
    weights = np.array(first["region"]["weights"])
    kept = (canon[vertices] - whole.centroid) @ np.array([0.8, 0.5, 0.33]) > 0
    # the slopes are local: a leg of the half also matches the other side's leg, so the region leans
    # to the kept side (quadruped 0.68 of the weight on 0.52 of the samples) without being only there
    assert weights[kept].sum() / weights.sum() > kept.mean() + 0.1


def test_a_whole_query_has_no_region(partial_dir):
    data_dir, _ = partial_dir
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        hits = _search(client, _obj(_shapes()["torus"]))["data"]
        assert all(h["region"] is None for h in hits)


def test_a_small_collection_reports_every_candidate_matched_and_nothing_cut(partial_dir):
    """Six models: a piece's candidates are all of them (no coarse pass: the global head holds the
    collection), each fully scored; a whole query's k hits are scored too. No deadline cut either."""
    data_dir, ids = partial_dir
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        piece = _search(client, _obj(_half(_shapes()["quadruped"])))
        whole = _search(client, _obj(_shapes()["torus"]))
    fits = {k: piece["partial"].pop(k) for k in ("fitted", "fitted_of", "fit_cut")}
    assert piece["partial"] == {"coarse_read": 0, "coarse_of": 0, "coarse_cut": False,
                                "scored": len(ids), "scored_of": len(ids), "score_cut": False}
    # every candidate chosen to be fitted was (the quadruped the piece was cut from among them)
    assert 1 <= fits["fitted"] == fits["fitted_of"] <= len(ids) and not fits["fit_cut"], fits
    assert {"partial.records", "partial.score", "partial.vote", "partial.peers", "partial.fit",
            "partial.regions"} <= set(piece["seconds"])
    assert "partial.peers" not in whole["seconds"]  # a whole query's hits keep the global order
    assert whole["partial"] == {"coarse_read": 0, "coarse_of": 0, "coarse_cut": False,
                                "scored": 5, "scored_of": 5, "score_cut": False,
                                "fitted": 0, "fitted_of": 0, "fit_cut": False}


def test_a_pieces_scores_meet_their_peers_through_the_stored_vectors(partial_dir, monkeypatch):
    """The peers' scores read every candidate's stored fused vector (one row each, none missing)."""
    from app.core import piece_rank

    data_dir, ids = partial_dir
    seen = []
    real = piece_rank.with_peers
    monkeypatch.setattr(piece_rank, "with_peers",
                        lambda found, vectors, *a: seen.append(np.array(vectors)) or real(found, vectors, *a))
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        _search(client, _obj(_half(_shapes()["quadruped"])))
    assert len(seen) == 1 and seen[0].shape[0] == len(ids) and seen[0].shape[1] > 30
    assert np.isfinite(seen[0]).all() and len(np.unique(seen[0], axis=0)) == len(ids)


def test_a_deadline_that_cuts_the_matching_is_reported(partial_dir, monkeypatch):
    """Both deadlines past at once, one model a chunk: the coarse pass reads one model of the six, the
    full scoring one candidate of the global head and that model; the answer says both were cut, and
    only the candidate scored has scores."""
    data_dir, ids = partial_dir
    monkeypatch.setattr(partial_service, "GLOBAL_KEEP", 3)
    monkeypatch.setattr(partial_service, "CHUNK", 1)
    monkeypatch.setattr(partial_service, "COARSE_BUDGET_S", 0.0)
    monkeypatch.setattr(partial_service, "SCORE_BUDGET_S", 0.0)
    read = []  # the peers read the vectors of the candidates scored, none here past the first
    real = partial_service.stored_vectors
    monkeypatch.setattr(partial_service, "stored_vectors",
                        lambda ctx, vid, model_ids: read.append(list(model_ids)) or real(ctx, vid, model_ids))
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        body = _search(client, _obj(_half(_shapes()["quadruped"])))
    assert read == []  # one candidate scored: it has no fellow to agree with, nothing is read
    work = body["partial"]
    assert (work["coarse_read"], work["coarse_of"], work["coarse_cut"]) == (1, len(ids), True)
    assert work["scored"] == 1 and work["scored_of"] in (3, 4) and work["score_cut"]
    assert len(body["data"]) == work["scored_of"]
    assert [h["forward"] is not None for h in body["data"]] == [True] + [False] * (work["scored_of"] - 1)


def test_a_piece_of_a_stored_model_moved_and_rescaled_is_fitted_onto_it_first(tmp_path):
    """The piece lies on the model it was cut from (app.core.piece_fit): that hit leads and says so with
    its numbers; no other model is said to hold it. The models are at the canonical resolution, so the
    piece keeps its whole's vertices, as a piece cut from a stored model does."""
    from tests.core.conftest import _random_rotation
    from tests.core.test_piece_fit import _canonical, _moved, _piece

    ctx = open_context(make_settings(tmp_path / "data", describe=DESCRIBE))
    shapes = {n: _canonical(m) if n != "torus" else m for n, m in _shapes().items()}
    ids = {n: ingestion.submit(ctx, _obj(m), f"{n}.obj", name=n, label=n).model.id for n, m in shapes.items()}
    describe_and_fit(ctx)
    piece = _moved(_piece(shapes["quadruped"]), _random_rotation(11), 25.4, mirror=False)
    with TestClient(create_app(make_settings(tmp_path / "data", describe=DESCRIBE))) as client:
        body = _search(client, _obj(piece))
    hits = body["data"]
    assert hits[0]["model_id"] == ids["quadruped"] and hits[0]["partial"]
    fit = hits[0]["fit"]
    assert fit["lies_on"] and fit["covered"] >= 0.8 and 0.6 <= fit["share"] <= 0.9 and not fit["mirrored"]
    assert not any(h["fit"] and h["fit"]["lies_on"] for h in hits[1:])
    assert "partial.fit" in body["seconds"]
