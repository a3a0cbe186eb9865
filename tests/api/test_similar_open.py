"""GET /models/{id}/similar ranks a stored model as POST /search ranks its mesh: an open one (a piece, a
one-sided scan) by partial matching, with forward / reverse scores; a closed one by the whole-shape
ranking. Small generated meshes, through httpx (TestClient)."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.services import ingestion
from app.services.context import open_context
from tests.api.test_partial_api import DESCRIBE, _half, _obj, _shapes, describe_and_fit
from tests.conftest import make_settings


@pytest.fixture(scope="module")
def collection(tmp_path_factory) -> tuple:
    """The five bodies and the torus, and a half of the quadruped stored as a model of its own."""
    data_dir = tmp_path_factory.mktemp("similar-open") / "data"
    ctx = open_context(make_settings(data_dir, describe=DESCRIBE))
    shapes = _shapes()
    ids = {name: ingestion.submit(ctx, _obj(mesh), f"{name}.obj", name=name).model.id
           for name, mesh in shapes.items()}
    ids["half"] = ingestion.submit(ctx, _obj(_half(shapes["quadruped"])), "half.obj", name="half").model.id
    describe_and_fit(ctx)
    return data_dir, ids


def _similar(client: TestClient, model_id: int, **params: str) -> list[dict]:
    r = client.get(f"/models/{model_id}/similar", params={"k": "5", **params})
    assert r.status_code == 200, r.text
    return r.json()["data"]


def test_an_open_stored_model_is_ranked_as_a_piece_and_finds_its_whole(collection):
    data_dir, ids = collection
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        r = client.get(f"/models/{ids['half']}/similar", params={"k": "5"})
        assert r.status_code == 200, r.text
        hits, work = r.json()["data"], r.json()["partial"]
        assert work["scored"] == work["scored_of"] >= 5 and not work["score_cut"]  # what the matching did
        assert ids["half"] not in [h["model_id"] for h in hits]  # itself excluded, as before
        assert hits[0]["model_id"] == ids["quadruped"]
        assert all(h["partial"] for h in hits)
        assert all(0.0 <= h["forward"] <= 1.0 and 0.0 <= h["reverse"] <= 1.0 for h in hits)
        assert 0.3 <= hits[0]["reverse"] <= 0.8  # the half covers about half of its whole
        # the same mesh uploaded ranks the same models first (its own stored copy aside)
        r = client.post("/search", files={"file": ("q.obj", _obj(_half(_shapes()["quadruped"])))},
                        data={"k": "6"})
        uploaded = [h["model_id"] for h in r.json()["data"] if h["model_id"] != ids["half"]]
        assert uploaded[0] == hits[0]["model_id"]


def test_partial_false_gives_an_open_model_the_whole_shape_ranking(collection):
    data_dir, ids = collection
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        hits = _similar(client, ids["half"], partial="false")
        assert not any(h["partial"] for h in hits)
        distances = [h["distance"] if h["rerank_distance"] is None else h["rerank_distance"] for h in hits]
        assert distances == sorted(distances)


def test_a_closed_model_keeps_the_whole_shape_ranking_unless_asked(collection):
    data_dir, ids = collection
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        r = client.get(f"/models/{ids['torus']}/similar", params={"k": "5"})
        auto = r.json()["data"]
        assert not any(h["partial"] for h in auto) and r.json()["partial"] is None
        assert [h["model_id"] for h in auto] == [h["model_id"] for h in _similar(client, ids["torus"],
                                                                               partial="false")]
        forced = _similar(client, ids["torus"], partial="true")
        assert all(h["partial"] for h in forced) and ids["torus"] not in [h["model_id"] for h in forced]


def test_a_bad_partial_option_on_similar_is_a_clear_422(collection):
    data_dir, ids = collection
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        r = client.get(f"/models/{ids['torus']}/similar", params={"partial": "maybe"})
        assert r.status_code == 422 and "partial" in r.text


def test_an_open_models_similar_search_stops_at_the_scoring_deadline_and_says_so(collection, monkeypatch):
    """Past SCORE_BUDGET_S the remaining candidates stay unscored (after the scored ones), and the answer
    reports the cut, as a piece's upload's does."""
    from app.services import partial as partial_service

    monkeypatch.setattr(partial_service, "CHUNK", 1)
    monkeypatch.setattr(partial_service, "SCORE_BUDGET_S", 0.0)
    data_dir, ids = collection
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        r = client.get(f"/models/{ids['half']}/similar", params={"k": "5"})
        assert r.status_code == 200, r.text
        work, hits = r.json()["partial"], r.json()["data"]
        assert work["score_cut"] and work["scored"] == 1 < work["scored_of"]
        assert hits[0]["forward"] is not None and all(h["forward"] is None for h in hits[1:])


def test_pieces_past_the_api_bound_are_busy_and_whole_queries_are_not(collection):
    """With every place of the piece bound held and no queue, a piece's /similar answers 503 busy +
    Retry-After at once; the same model's whole-shape ranking still answers; a freed place serves it."""
    from app.config import BudgetSettings

    data_dir, ids = collection
    settings = make_settings(data_dir, describe=DESCRIBE,
                             piece_budget=BudgetSettings(concurrency=1, queue=0, timeout_s=5.0))
    with TestClient(create_app(settings)) as client:
        pieces = client.app.state.runtime.pieces
        with pieces.hold():  # another client's piece, being matched
            r = client.get(f"/models/{ids['half']}/similar", params={"k": "5"})
            assert r.status_code == 503, r.text
            assert r.json()["error"]["code"] == "busy" and "Retry-After" in r.headers
            assert _similar(client, ids["half"], partial="false")  # the whole-shape ranking: no place needed
            r = client.post("/search", files={"file": ("q.obj", _obj(_half(_shapes()["quadruped"])))},
                            data={"k": "5"})
            assert r.status_code == 503 and r.json()["error"]["code"] == "busy"
        hits = _similar(client, ids["half"])
        assert hits[0]["model_id"] == ids["quadruped"] and pieces.active == 0


def test_one_client_past_its_share_of_the_piece_queue_is_told_429(collection):
    """The queue holds 2, a client at most 1 of them: its second waiting piece is refused 429 +
    Retry-After by the per-client bound's middleware, and its first is served once the place frees."""
    import threading

    from app.config import BudgetSettings

    data_dir, ids = collection
    settings = make_settings(data_dir, describe=DESCRIBE,
                             piece_budget=BudgetSettings(concurrency=1, queue=2, timeout_s=30.0))
    with TestClient(create_app(settings)) as client:
        pieces = client.app.state.runtime.pieces
        answers: list[int] = []
        with pieces.hold():
            first = threading.Thread(target=lambda: answers.append(
                client.get(f"/models/{ids['half']}/similar").status_code))
            first.start()
            for _ in range(500):
                if pieces.waiting == 1:
                    break
                threading.Event().wait(0.01)
            assert pieces.waiting == 1
            r = client.get(f"/models/{ids['half']}/similar")
            assert r.status_code == 429 and "Retry-After" in r.headers, r.text
        first.join(60)
        assert answers == [200] and pieces.active == 0 and pieces.waiting == 0
