"""Inputs that used to corrupt state for good: metadata JSON cannot round-trip (issue 12, item 1).

Every refused request must leave the store as it was; every accepted one must serialise back out.
"""

from __future__ import annotations

import json
import shutil

import pytest
import trimesh
from fastapi.testclient import TestClient

from app.main import create_app
from app.services import ingestion
from app.services.context import open_context
from app.services.errors import InvalidInputError
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
