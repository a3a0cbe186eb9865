"""The variants over HTTP: upload a model and a rescaled, moved copy of it; the job result, the model,
GET /models/{id}/variants and /similar name the relation; a reviewer's decision is guarded and kept."""

from __future__ import annotations

import numpy as np
import trimesh
from fastapi.testclient import TestClient

from app.main import create_app
from tests.conftest import make_settings, wait_for, wait_job


def _upload(client, name: str, data: bytes, **headers):
    return client.post("/models", files={"file": (name, data)}, headers=headers)


def test_variant_found_at_ingest_shown_and_decided(data_dir, corpus):
    path, _ = corpus.held_out[0]
    tm = trimesh.load(path, process=False)
    copy = tm.copy()
    copy.apply_scale(25.4)
    copy.apply_translation([100.0, 0.0, 0.0])  # in inches, moved: other bytes, another format
    with TestClient(create_app(make_settings(data_dir))) as client:
        first = _upload(client, path.name, path.read_bytes())
        assert first.status_code == 202 and first.json()["variants"] is None  # found by the job
        a = first.json()["model_id"]
        assert wait_job(client, first.json()["job_id"])["state"] == "done"
        second = _upload(client, "inches.stl", copy.export(file_type="stl"))
        b = second.json()["model_id"]
        job = wait_job(client, second.json()["job_id"])
        assert job["state"] == "done"
        assert [(v["model_id"], v["relation"]) for v in job["result"]["variants"]] == [(a, "rescaled")]
        assert job["timings"]["variants"] > 0

        model = client.get(f"/models/{b}").json()
        assert model["variants"] == job["result"]["variants"]
        listed = client.get(f"/models/{a}/variants").json()
        assert listed["count"] == 1
        v = listed["data"][0]
        assert (v["model_id"], v["relation"], v["same_triangles"]) == (b, "rescaled", True)
        assert abs(v["scale"] - 25.4) < 1e-4 and v["decision"] is None
        assert np.allclose(np.asarray(v["transform"])[:3, 3], [100.0, 0.0, 0.0], atol=1e-3)
        assert client.get("/models/999999/variants").status_code == 404

        def hit():  # the live index picks the new vector up on its next poll
            r = client.get(f"/models/{a}/similar", params={"k": 20})
            rows = {h["model_id"]: h for h in r.json()["data"]} if r.status_code == 200 else {}
            return rows if b in rows else None

        rows = wait_for(hit, timeout_s=30)
        assert rows[b]["relation"] == "rescaled"
        assert all(h["relation"] is None for i, h in rows.items() if i != b)

        # same bytes again: the existing model, with its variants in the reply
        again = _upload(client, "inches-again.stl", copy.export(file_type="stl"))
        assert again.status_code == 200 and again.json()["variants"][0]["model_id"] == a

        url = f"/models/{a}/variants/{b}/decision"
        r = client.post(url, json={"decision": "keep_both", "note": "left and right"})
        assert r.status_code == 201, r.text
        assert r.json()["decision"] == "keep_both"
        assert client.post(url, json={"decision": "merge"}).status_code == 422
        same = client.post(f"/models/{a}/variants/{a}/decision", json={"decision": "keep_both"})
        assert same.status_code == 422
        assert client.post(f"/models/{a}/variants/999999/decision",
                           json={"decision": "keep_both"}).status_code == 404
        kept = client.get(f"/models/{b}/variants").json()["data"][0]
        assert kept["decision"]["decision"] == "keep_both" and kept["decision"]["note"] == "left and right"
        assert client.get(f"/models/{a}").status_code == 200 and client.get(f"/models/{b}").status_code == 200


def test_decision_needs_the_write_token_when_one_is_set(data_dir):
    writer = "writer-" + "w" * 32  # tokens are 32 characters or more
    settings = make_settings(data_dir, api_token=writer)
    with TestClient(create_app(settings)) as client:
        ids = [m["id"] for m in client.get("/models", params={"limit": 2}).json()["data"]]
        url = f"/models/{ids[0]}/variants/{ids[1]}/decision"
        assert client.post(url, json={"decision": "not_variant"}).status_code == 401
        r = client.post(url, json={"decision": "not_variant"}, headers={"Authorization": f"Bearer {writer}"})
        assert r.status_code == 201


def test_search_hits_carry_the_relation_verified_for_the_query(data_dir, corpus):
    """POST /search with a query that is not stored: a mirrored, moved copy of a stored model gets
    `relation` and its evidence on that model's hit; a query of another shape gets none."""
    path, _ = corpus.held_out[0]
    tm = trimesh.load(path, process=False)
    mirror = tm.copy()
    mirror.apply_transform(np.diag([-1.0, 1.0, 1.0, 1.0]))
    mirror.apply_translation([5.0, 0.0, 0.0])
    with TestClient(create_app(make_settings(data_dir))) as client:
        first = _upload(client, path.name, path.read_bytes())
        a = first.json()["model_id"]
        assert wait_job(client, first.json()["job_id"])["state"] == "done"

        def hits(data: bytes, name: str):
            r = client.post("/search", files={"file": (name, data)}, data={"k": "20"})
            assert r.status_code == 200, r.text
            rows = {h["model_id"]: h for h in r.json()["data"]}
            return (rows, r.json()["seconds"]) if a in rows else None

        rows, seconds = wait_for(lambda: hits(mirror.export(file_type="ply"), "mirror.ply"), timeout_s=30)
        assert rows[a]["relation"] == "mirrored"
        evidence = rows[a]["evidence"]
        assert evidence["mirrored"] and evidence["same_triangles"] and evidence["confidence"] == 1.0
        t = np.asarray(evidence["transform"])  # the query onto the stored model
        assert np.linalg.det(t[:3, :3]) < 0 and abs(t[0, 3] - 5.0) < 1e-3
        assert all(h["relation"] is None and h["evidence"] is None for i, h in rows.items() if i != a)
        assert seconds["variants"] >= 0
        other, _ = corpus.held_out[1]
        r = client.post("/search", files={"file": (other.name, other.read_bytes())}, data={"k": "20"})
        assert r.status_code == 200
        assert [h["model_id"] for h in r.json()["data"] if h["relation"] is not None] == []


def test_decisions_keep_a_bounded_history_refuse_odd_notes_and_respect_the_disk_floor(data_dir, monkeypatch):
    """A pair keeps its last KEPT_DECISIONS decisions, the latest shown; a note with a control or
    bidi-override character is 422; under the storage floor a decision is 507 and stores nothing."""
    from app.services import space
    from app.storage.variants import KEPT_DECISIONS

    with TestClient(create_app(make_settings(data_dir))) as client:
        a, b = [m["id"] for m in client.get("/models", params={"limit": 2}).json()["data"]]
        url = f"/models/{a}/variants/{b}/decision"
        for i in range(KEPT_DECISIONS + 5):
            decision = "keep_both" if i % 2 else "not_variant"
            assert client.post(url, json={"decision": decision, "note": f"n{i}"}).status_code == 201
        db = client.app.state.runtime.ctx.db
        with db.read() as conn:
            rows = conn.execute("SELECT note FROM variant_decisions WHERE low_id = ? AND high_id = ?"
                                " ORDER BY seq", (min(a, b), max(a, b))).fetchall()
        assert [r[0] for r in rows] == [f"n{i}" for i in range(5, KEPT_DECISIONS + 5)]
        with db.read() as conn:
            from app.storage import variants as variants_repo
            assert variants_repo.decisions_of(conn, a)[b]["note"] == f"n{KEPT_DECISIONS + 4}"
        for note in ("a\u0000b", "\u202e evil", "bell\u0007"):
            r = client.post(url, json={"decision": "keep_both", "note": note})
            assert r.status_code == 422 and "note: contains" in r.json()["error"]["message"], note
        monkeypatch.setattr(space, "free_bytes", lambda path: 1024 * 1024)  # under the 512 MB floor
        r = client.post(url, json={"decision": "keep_both", "note": "while full"})
        assert r.status_code == 507 and r.json()["error"]["code"] == "insufficient_storage"
        with db.read() as conn:
            notes = [n for (n,) in conn.execute("SELECT note FROM variant_decisions").fetchall()]
        assert "while full" not in notes and len(notes) == KEPT_DECISIONS
