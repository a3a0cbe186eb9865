"""With no vocabulary: /readyz says why (503), searches answer 503, and a first vocabulary gets fitted."""

from __future__ import annotations

from fastapi.testclient import TestClient

from app.main import create_app
from tests.conftest import make_settings, wait_for, wait_job


def test_no_vocabulary_until_enough_models_then_one_is_fitted(settings, corpus):
    settings = make_settings(settings.data_dir, auto_vocabulary_min_models=4, vocabulary_size=8)
    with TestClient(create_app(settings)) as client:
        r = client.get("/readyz")
        assert r.status_code == 503
        checks = r.json()["checks"]
        assert checks["database"] and not checks["vocabulary"] and "rebuild" in checks["hint"]
        path, _ = corpus.seeded[0]
        r = client.post("/search", files={"file": (path.name, path.read_bytes())})
        assert r.status_code == 503 and r.json()["error"]["code"] == "not_ready"
        jobs = []
        for path, label in corpus.seeded[:4]:
            jobs.append(
                client.post(
                    "/models", files={"file": (path.name, path.read_bytes())}, data={"label": label}
                ).json()["job_id"]
            )
        assert all(wait_job(client, j)["state"] == "done" for j in jobs)
        wait_for(lambda: client.get("/readyz").status_code == 200, timeout_s=60)
        ready = client.get("/readyz").json()["checks"]
        assert ready["indexed_models"] == 4 and ready["workers_alive"] == 1
        hits = client.get(f"/models/{client.get('/models').json()['data'][0]['id']}/similar").json()
        assert hits["count"] == 3


def test_queue_limit_answers_503_and_stores_nothing(settings, corpus):
    settings = make_settings(settings.data_dir, workers=0, queue_limit=1)
    with TestClient(create_app(settings)) as client:
        first, second = corpus.seeded[0][0], corpus.seeded[1][0]
        assert client.post("/models", files={"file": (first.name, first.read_bytes())}).status_code == 202
        r = client.post("/models", files={"file": (second.name, second.read_bytes())})
        assert r.status_code == 503 and r.json()["error"]["code"] == "queue_full"
        assert client.get("/models").json()["count"] == 1
        assert len(list((settings.data_dir / "meshes").rglob("*.obj"))) == 1  # no orphan blob
