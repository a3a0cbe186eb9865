"""Upload -> job done -> search finds it first; duplicates; delete; bad input; with the lifespan running."""

from __future__ import annotations

import numpy as np
from fastapi.testclient import TestClient

from app.main import create_app
from app.services import ingestion
from app.storage.blobs import BlobStore
from tests.conftest import make_settings, wait_job


def _upload(client, path, label=None, **fields):
    data = {"label": label} if label else {}
    data.update(fields)
    return client.post("/models", files={"file": (path.name, path.read_bytes())}, data=data)


def _search(client, path, k=5, label=None):
    data = {"k": str(k)}
    if label:
        data["label"] = label
    return client.post("/search", files={"file": (path.name, path.read_bytes())}, data=data)


def test_upload_ingest_search_duplicate_and_delete(data_dir, corpus):
    path, label = corpus.held_out[0]
    with TestClient(create_app(make_settings(data_dir))) as client:
        r = _upload(client, path, label, name="query-one", metadata='{"source": "test"}')
        assert r.status_code == 202, r.text
        body = r.json()
        assert body["status"] == "queued" and body["job_id"] is not None
        job = wait_job(client, body["job_id"])
        assert job["state"] == "done", job
        assert job["timings"]["describe.eigen"] > 0
        model = client.get(f"/models/{body['model_id']}").json()
        assert model["status"] == "ready" and model["label"] == label
        assert model["metadata"] == {"source": "test"} and model["name"] == "query-one"

        # the same content again: the existing model, no new work
        again = _upload(client, path, "other-label")
        assert again.status_code == 200
        assert again.json()["model_id"] == body["model_id"] and again.json()["job_id"] is None

        # the poller adds the worker's vector to the API's index; then the model is its own nearest
        def found():
            r = _search(client, path)
            return (
                r.json()
                if r.status_code == 200 and r.json()["data"][0]["model_id"] == body["model_id"]
                else None
            )

        from tests.conftest import wait_for

        result = wait_for(found, timeout_s=30)
        top = result["data"][0]
        assert top["distance"] < 1e-5 and top["rank"] == 1 and top["label"] == label
        assert [h["rank"] for h in result["data"]] == list(range(1, len(result["data"]) + 1))
        # ordered by the fusion re-rank's distance (on by default); distance stays the index's L1
        assert all(h["rerank_distance"] is not None for h in result["data"])
        # (the first, a stored copy at 0, is a distinct nearest match: first whatever its re-rank distance)
        assert np.all(np.diff([h["rerank_distance"] for h in result["data"][1:]]) >= 0)
        assert result["seconds"]["describe"] > 0 and "search" in result["seconds"]

        # label filter
        other = next(lbl for _, lbl in corpus.seeded if lbl != label)
        filtered = _search(client, path, k=10, label=other).json()
        assert filtered["count"] > 0 and {h["label"] for h in filtered["data"]} == {other}

        # similar by stored model: itself excluded
        sim = client.get(f"/models/{body['model_id']}/similar", params={"k": 3}).json()
        assert sim["count"] == 3 and body["model_id"] not in [h["model_id"] for h in sim["data"]]

        # mesh download is the uploaded content
        assert client.get(f"/models/{body['model_id']}/mesh").content == path.read_bytes()

        # delete: gone from the index, the database and the blob store
        blobs = BlobStore(data_dir.resolve())
        mesh_file = blobs.mesh_path(model["sha256"], model["file_type"])
        assert mesh_file.is_file() and blobs.description_path(model["id"]).is_file()
        admin = {
            "X-Admin-Token": "test-token-kkkkkkkkkkkkkkkkkkkkk"
        }  # no SHAPEBAG_API_TOKEN: deletion needs the admin token
        assert client.delete(f"/models/{model['id']}").status_code == 401
        assert client.delete(f"/models/{model['id']}", headers=admin).status_code == 204
        assert client.get(f"/models/{model['id']}").status_code == 404
        assert client.delete(f"/models/{model['id']}", headers=admin).json()["error"]["code"] == "not_found"
        assert not mesh_file.exists() and not blobs.description_path(model["id"]).exists()
        after = _search(client, path, k=20).json()
        assert model["id"] not in [h["model_id"] for h in after["data"]]
        listed = client.get("/models", params={"limit": 100}).json()
        assert model["id"] not in [m["id"] for m in listed["data"]] and listed["count"] == len(corpus.seeded)


def test_bad_uploads_get_clear_errors_and_change_nothing(data_dir, corpus, tmp_path):
    settings = make_settings(data_dir, max_upload_bytes=20_000)
    with TestClient(create_app(settings)) as client:
        before = client.get("/models").json()["count"]
        for route in ("/models", "/search"):  # one extension check, one answer, on both doors
            r = client.post(route, files={"file": ("shape.xyz", b"v 0 0 0\n")})
            assert r.status_code == 415 and r.json()["error"]["code"] == "unsupported_format", route
            assert "unsupported mesh format" in r.json()["error"]["message"]
        big = b"v 0 0 0\n" * 5000  # 40 kB > 20 kB
        r = client.post("/models", files={"file": ("big.obj", big)})
        assert r.status_code == 413 and r.json()["error"]["code"] == "payload_too_large"
        r = client.post("/models", files={"file": ("a.obj", b"v 0 0 0\n")}, data={"metadata": "[1, 2"})
        assert r.status_code == 422 and "metadata" in r.json()["error"]["message"]
        r = client.post("/models", files={"file": ("a.obj", b"v 0 0 0\n")}, data={"label": "x" * 101})
        assert r.status_code == 422 and r.json()["error"]["message"].startswith("label:")
        r = client.post("/models", data={"name": "no file"})
        assert r.status_code == 422
        assert client.get("/models").json()["count"] == before

        # a file that parses as OBJ but is no surface: the API refuses it (422) and stores nothing...
        flat = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"
        r = client.post("/models", files={"file": ("flat.obj", flat)})
        assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_mesh"
        assert client.get("/models").json()["count"] == before
        # ...and one that got in another way (bulk ingest): its job fails at once with the reason
        sub = ingestion.submit(client.app.state.runtime.ctx, flat, "flat.obj")
        job = wait_job(client, sub.job_id)
        assert job["state"] == "failed" and job["attempts"] == 1 and job["error"]
        model = client.get(f"/models/{sub.model.id}").json()
        assert model["status"] == "failed" and model["error"] == job["error"]

        r = client.post("/search", files={"file": ("q.obj", b"v 0 0 0\n")})
        assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_mesh"
        r = client.post("/search", files={"file": ("q.obj", b"v 0 0 0\n")}, data={"k": "0"})
        assert r.status_code == 422 and "k must be" in r.json()["error"]["message"]
        assert client.get("/models/999999/similar").status_code == 404
        failed_id = client.get("/models", params={"status": "failed"}).json()["data"][0]["id"]
        r = client.get(f"/models/{failed_id}/similar")
        assert r.status_code == 409 and r.json()["error"]["code"] == "conflict"
        assert client.get("/jobs/999999").json()["error"]["code"] == "not_found"


def test_labels_lists_every_label_in_use_with_its_count(data_dir, corpus):
    with TestClient(create_app(make_settings(data_dir))) as client:
        models = client.get("/models", params={"limit": 500}).json()["data"]
        expected: dict[str, int] = {}
        for m in models:
            if m["label"]:
                expected[m["label"]] = expected.get(m["label"], 0) + 1
        assert expected  # the seeded collection is labelled
        body = client.get("/labels").json()
        assert body["data"] == [{"label": k, "models": v} for k, v in sorted(expected.items())]

        path, _ = corpus.held_out[0]
        up = _upload(client, path, "brand-new-label")
        assert up.status_code == 202
        # a model counts under its label from upload on, whatever its status
        labels = {item["label"]: item["models"] for item in client.get("/labels").json()["data"]}
        assert labels["brand-new-label"] == 1 and len(labels) == len(expected) + 1
        # "labels" is a route of its own, not a model id
        assert client.get("/models/labels").status_code == 422
