"""Inputs that used to corrupt state for good: metadata JSON cannot round-trip (issue 12, item 1).

Every refused request must leave the store as it was; every accepted one must serialise back out.
"""

from __future__ import annotations

import contextlib
import json
import shutil

import pytest
import trimesh
from fastapi.testclient import TestClient

from app.main import create_app
from app.services import catalog, ingestion
from app.services.context import open_context
from app.services.errors import InvalidInputError
from app.storage import models as models_repo
from tests.conftest import make_settings, wait_for
from tests.reliability.corpus import bad_metadata, good_metadata, obj_text
from tests.reliability.helpers import MULTIPART_HEADERS, multipart, snapshot


@pytest.fixture(scope="module")
def served(seeded_dir, tmp_path_factory):
    data = shutil.copytree(seeded_dir, tmp_path_factory.mktemp("state") / "data")
    with TestClient(create_app(make_settings(data))) as client:
        wait_for(lambda: client.get("/readyz").status_code == 200, timeout_s=60)
        yield client, data


def _mesh(i: int) -> bytes:
    """A distinct good mesh per call (so no upload is answered by deduplication)."""
    s = trimesh.creation.icosphere(subdivisions=2)
    return obj_text(s.vertices * [1.0, 1.0 + 0.01 * (i + 1), 0.9], s.faces)


def test_the_metadata_corpus_covers_each_class():
    names = [case for case, _ in bad_metadata()]
    assert len(names) == len(set(names)) >= 40
    for prefix in ("surrogate-", "nonfinite-", "deep-objects-", "deep-arrays-", "big-int-", "duplicate-key"):
        assert any(n.startswith(prefix) for n in names), prefix


def test_metadata_json_cannot_round_trip_is_refused_and_nothing_is_stored(served):
    client, data = served
    before = snapshot(data)
    wrong = []
    for i, (case, raw) in enumerate(bad_metadata()):
        body = multipart("ok.obj", _mesh(i), {"metadata": raw})
        r = client.post("/models", content=body, headers=MULTIPART_HEADERS)
        if r.status_code != 422 or "metadata" not in r.json()["error"]["message"]:
            wrong.append(f"{case}: {r.status_code} {r.text[:200]}")
    assert not wrong, "\n".join(wrong)
    assert snapshot(data) == before
    assert client.get("/models", params={"limit": 500}).status_code == 200  # every page still serialises


def test_metadata_at_the_edges_is_stored_and_served_back_unchanged(served):
    client, _ = served
    for i, raw in enumerate(good_metadata()):
        body = multipart("edge.obj", _mesh(100 + i), {"metadata": raw})
        r = client.post("/models", content=body, headers=MULTIPART_HEADERS)
        assert r.status_code == 202, r.text
        got = client.get(f"/models/{r.json()['model_id']}")
        assert got.status_code == 200 and got.json()["metadata"] == json.loads(raw)
    assert client.get("/models", params={"limit": 500}).status_code == 200


def test_every_door_that_stores_metadata_checks_it(settings):
    """Not only the API's parser: ingestion.submit (the CLI's bulk ingest too) refuses a bad dict."""
    ctx = open_context(settings)
    for bad in ({"a": float("nan")}, {"a": "\ud800"}, {"a": 10**30}, {"\udfff": 1}, {"a": {1, 2}}):
        with pytest.raises(InvalidInputError, match="metadata"):
            ingestion.submit(ctx, _mesh(0), "x.obj", metadata=bad)  # type: ignore[arg-type]
    with ctx.db.read() as conn:
        assert conn.execute("SELECT COUNT(*) FROM models").fetchone()[0] == 0


# --- DELETE racing a re-upload of the same bytes (issue 12, item 2) ---------------------------------
# Each window is opened deterministically by a hook at the exact point between two steps (no sleeps).


def _ready_model(ctx, data: bytes):
    from app.worker.runner import Worker

    sub = ingestion.submit(ctx, data, "race.obj")
    Worker(ctx, "race").run_forever(exit_when_idle=True)
    return catalog.get_model(ctx, sub.model.id)


def _ingest_all(ctx) -> None:
    from app.worker.runner import Worker

    Worker(ctx, "race").run_forever(exit_when_idle=True)


def test_delete_landing_between_the_blob_write_and_the_insert(settings, monkeypatch):
    """upload: file written ... [delete commits and removes the file] ... row inserted -> the new model
    must still have its file (before: it pointed at nothing, failed 3 times, and blocked the bytes)."""
    ctx = open_context(settings)
    data = _mesh(7)
    old = _ready_model(ctx, data)
    real_put = ctx.blobs.put_mesh

    def put_then_delete(blob: bytes, file_type: str):
        out = real_put(blob, file_type)
        monkeypatch.setattr(ctx.blobs, "put_mesh", real_put)  # once
        catalog.delete_model(ctx, None, old.id)
        return out

    monkeypatch.setattr(ctx.blobs, "put_mesh", put_then_delete)
    sub = ingestion.submit(ctx, data, "race.obj")
    assert sub.model.id != old.id and sub.created, "answered with the model being deleted"
    assert ctx.blobs.mesh_path(sub.model.sha256, "obj").read_bytes() == data
    _ingest_all(ctx)
    assert catalog.get_model(ctx, sub.model.id).status == "ready"


def test_upload_landing_between_the_delete_commit_and_the_file_removal(settings):
    """delete: row gone (committed) ... [upload of the same bytes] ... file removal -> the file the
    new model needs must survive (before: the delete removed it after the upload had inserted)."""
    ctx = open_context(settings)
    data = _mesh(8)
    old = _ready_model(ctx, data)
    uploaded = []

    class Hook:  # live.remove runs after the delete's commit, before its file clean-up
        def remove(self, ids):
            uploaded.append(ingestion.submit(ctx, data, "race.obj"))

    catalog.delete_model(ctx, Hook(), old.id)  # type: ignore[arg-type]
    (sub,) = uploaded
    assert sub.model.id != old.id
    assert ctx.blobs.mesh_path(sub.model.sha256, "obj").read_bytes() == data
    _ingest_all(ctx)
    assert catalog.get_model(ctx, sub.model.id).status == "ready"
    assert not list(ctx.blobs.mesh_path(sub.model.sha256, "obj").parent.glob(".*.tmp"))  # no trash left


def test_a_failed_delete_transaction_keeps_the_file(settings, monkeypatch):
    ctx = open_context(settings)
    data = _mesh(9)
    old = _ready_model(ctx, data)

    real_write = ctx.db.write

    @contextlib.contextmanager
    def commit_fails():  # the delete's transaction fails at its end, after the file was moved aside
        with real_write() as conn:
            yield conn
            raise RuntimeError("disk went away")

    monkeypatch.setattr(ctx.db, "write", commit_fails)
    with pytest.raises(RuntimeError):
        catalog.delete_model(ctx, None, old.id)
    assert catalog.get_model(ctx, old.id).status == "ready"  # rolled back: the row is there...
    assert ctx.blobs.mesh_path(old.sha256, "obj").read_bytes() == data  # ...and so is its file


def test_a_failed_model_is_retried_by_uploading_its_bytes_again(served):
    client, data_dir = served
    ctx = client.app.state.runtime.ctx
    data = _mesh(10)
    r = client.post("/models", content=multipart("retry.obj", data), headers=MULTIPART_HEADERS)
    model_id = r.json()["model_id"]
    wait_for(lambda: client.get(f"/models/{model_id}").json()["status"] == "ready", timeout_s=60)
    with ctx.db.write() as conn:  # as if every attempt had hit a transient fault
        models_repo.set_failed(conn, model_id, "gave up after 3 attempts: FileNotFoundError")
    again = client.post("/models", content=multipart("retry.obj", data), headers=MULTIPART_HEADERS)
    assert again.status_code == 202 and again.json()["model_id"] == model_id
    assert again.json()["job_id"] is not None and again.json()["status"] == "queued"
    wait_for(lambda: client.get(f"/models/{model_id}").json()["status"] == "ready", timeout_s=60)
    third = client.post("/models", content=multipart("retry.obj", data), headers=MULTIPART_HEADERS)
    assert third.status_code == 200 and third.json()["job_id"] is None  # ready: plain deduplication


def test_rows_stored_before_validation_still_serialise(served):
    """A database written before metadata was validated may hold NaN, lone surrogates, deep nesting
    or huge integers: those rows read back with a placeholder instead of failing every page (500)."""
    client, data = served
    ctx = client.app.state.runtime.ctx
    legacy = {
        "nan": '{"a": NaN}',
        "surrogate": '{"a": "\\ud800"}',
        "deep": '{"a": ' * 300 + "1" + "}" * 300,
        "digits": '{"a": ' + "9" * 5000 + "}",
        "not-an-object": "[1, 2]",
    }
    ids = {}
    for i, (case, text) in enumerate(legacy.items()):
        data_bytes = _mesh(200 + i)
        sub = ingestion.submit(ctx, data_bytes, f"{case}.obj")
        with ctx.db.write() as conn:  # as an old version stored it, unchecked
            conn.execute("UPDATE models SET metadata = ? WHERE id = ?", (text, sub.model.id))
        ids[case] = sub.model.id
    for case, model_id in ids.items():
        r = client.get(f"/models/{model_id}")
        assert r.status_code == 200, (case, r.text[:200])
        meta = r.json()["metadata"]
        assert meta == {} if case == "not-an-object" else "unreadable" in meta, (case, meta)
    assert client.get("/models", params={"limit": 500}).status_code == 200


def test_a_mesh_whose_file_just_left_is_404_not_500(served):
    """GET /models/{id}/mesh read the row, then a delete took the file: before, FileResponse failed (500)."""
    client, _ = served
    ctx = client.app.state.runtime.ctx
    sub = ingestion.submit(ctx, _mesh(300), "leaving.obj")
    hidden = ctx.blobs.hide_mesh(sub.model.sha256, "obj")  # the state inside a delete's transaction
    assert hidden is not None
    try:
        r = client.get(f"/models/{sub.model.id}/mesh")
        assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"
    finally:
        hidden.rename(ctx.blobs.mesh_path(sub.model.sha256, "obj"))
    assert client.get(f"/models/{sub.model.id}/mesh").status_code == 200
