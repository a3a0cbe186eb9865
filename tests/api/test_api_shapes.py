"""One word for a job's progress, timings that are only timings, and duplicates that say so
(issue 14 item 7)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import trimesh
from fastapi.testclient import TestClient

from app.api.schemas import JobPublic, split_job_timings
from app.main import create_app
from app.storage.jobs import JobRecord
from tests.conftest import make_settings

ADMIN = {"X-Admin-Token": "test-token-kkkkkkkkkkkkkkkkkkkkk"}


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    settings = make_settings(tmp_path_factory.mktemp("d") / "data", workers=0)  # jobs stay queued
    with TestClient(create_app(settings)) as c:
        yield c


@pytest.fixture(scope="module")
def ball() -> bytes:
    return trimesh.creation.icosphere(subdivisions=2).export(file_type="obj").encode()


def _record(**timings) -> JobRecord:
    return JobRecord(
        id=7, kind="rebuild_vocabulary", state="done", model_id=None, attempts=1, lease_until=None,
        worker=None, error=None, created_at="t0", updated_at="t1", payload={}, timings=timings,
    )


def test_a_jobs_timings_hold_seconds_only_and_the_rest_is_its_result() -> None:
    job = JobPublic.of(_record(
        load_descriptions=0.5, fit=1.25, encode_and_index=0.25, pruned_versions=1.0,
        encoded_after_swap=0.0, vocabulary_id=3, models=48,
    ))
    assert job.timings == {"load_descriptions": 0.5, "fit": 1.25, "encode_and_index": 0.25}
    assert job.result == {"pruned_versions": 1, "encoded_after_swap": 0, "vocabulary_id": 3, "models": 48}
    assert isinstance(job.result["pruned_versions"], int)  # a count, not 1.0
    assert job.status == job.model_dump()["state"] == "done"


def test_a_stored_result_object_and_text_values_go_to_result() -> None:
    stored = {"load": 0.1, "note": "model deleted", "result": {"vocabulary_id": 2}}
    timings, result = split_job_timings(stored)
    assert timings == {"load": 0.1} and result == {"note": "model deleted", "vocabulary_id": 2}


def test_jobs_and_the_rebuild_reply_say_status_like_models_do(client: TestClient, ball: bytes) -> None:
    up = client.post("/models", files={"file": ("ball.obj", ball)}, data={"name": "ball"})
    assert up.status_code == 202 and up.json()["status"] == "queued"
    job = client.get(f"/jobs/{up.json()['job_id']}").json()
    assert job["status"] == "queued" and job["state"] == job["status"]  # the old name kept, same value
    assert job["timings"] == {} and job["result"] == {}
    rebuild = client.post("/admin/vocabulary/rebuild", headers=ADMIN)
    assert rebuild.status_code == 202
    assert rebuild.json()["status"] == "queued" and rebuild.json()["state"] == "queued"


def test_the_old_field_is_marked_deprecated_in_the_openapi(client: TestClient) -> None:
    schemas = client.get("/openapi.json").json()["components"]["schemas"]
    for name in ("JobPublic", "JobAccepted"):
        props = schemas[name]["properties"]
        assert props["state"].get("deprecated") is True and not props["status"].get("deprecated")
        assert "status" in schemas[name]["required"]
    assert {"timings", "result"} <= set(schemas["JobPublic"]["properties"])


def test_identical_bytes_under_a_new_name_say_the_stored_name_was_kept(client: TestClient) -> None:
    data = trimesh.creation.box().export(file_type="obj").encode()
    first = client.post("/models", files={"file": ("box.obj", data)}, data={"name": "box-1", "label": "box"})
    assert first.status_code == 202 and first.json()["duplicate_of"] is None and first.json()["note"] is None
    again = client.post("/models", files={"file": ("b.obj", data)}, data={"name": "box-2", "label": "crate"})
    assert again.status_code == 200
    body = again.json()
    assert body["duplicate_of"] == first.json()["model_id"] == body["model_id"] and body["job_id"] is None
    assert "'box-1'" in body["note"] and "name and label were kept" in body["note"]
    assert body["model"]["name"] == "box-1" and body["model"]["label"] == "box"
    same = client.post("/models", files={"file": ("b.obj", data)}, data={"name": "box-1"})
    assert same.status_code == 200 and "kept" not in same.json()["note"]  # nothing sent was dropped


def test_readme_documents_status_and_result() -> None:
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert "duplicate_of" in readme and "result" in readme
