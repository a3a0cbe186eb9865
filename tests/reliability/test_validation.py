"""Requests answered 500 or wrongly accepted (issue 12, items 8-10): NUL in a static path, integers
beyond any sane range in queries and payloads, duplicate multipart fields. Each is a 422/404 at the
door, and nothing is stored or queued."""

from __future__ import annotations

import shutil

import pytest
import trimesh
from fastapi.testclient import TestClient

from app.main import create_app
from tests.conftest import make_settings, wait_for
from tests.reliability.corpus import duplicate_field_bodies, obj_text
from tests.reliability.helpers import BOUNDARY, MULTIPART_HEADERS, snapshot

ADMIN = {"X-Admin-Token": "test-token-kkkkkkkkkkkkkkkkkkkkk"}


@pytest.fixture(scope="module")
def served(seeded_dir, tmp_path_factory):
    data = shutil.copytree(seeded_dir, tmp_path_factory.mktemp("validation") / "data")
    with TestClient(create_app(make_settings(data)), raise_server_exceptions=False) as client:
        wait_for(lambda: client.get("/readyz").status_code == 200, timeout_s=60)
        yield client, data


@pytest.mark.parametrize(
    "path",
    [
        "/static/app.js%00.css",
        "/static/%00",
        "/static/app.js%00",
        "/static/..%2fapp.js",
        "/static/%2e%2e",
        "/static/" + "a" * 5000,
        "/static/%ff%fe",
        "/static/app.js%0a",
    ],
)
def test_odd_static_names_are_404(served, path):
    client, _ = served
    r = client.get(path)
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found", (path, r.text[:200])
    assert client.get("/static/app.js").status_code == 200


@pytest.mark.parametrize(
    "query",
    [
        {"offset": "99999999999999999999"},
        {"offset": str(2**63)},
        {"offset": str(2**64)},
        {"offset": "-1"},
        {"offset": "9" * 5000},
        {"limit": "99999999999999999999"},
        {"limit": "0"},
    ],
)
def test_out_of_range_page_queries_are_422(served, query):
    client, _ = served
    r = client.get("/models", params=query)
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_request", r.text[:200]


@pytest.mark.parametrize(
    "path",
    [
        "/models/1/similar?k=99999999999999999999",
        "/models/1/similar?k=0",
        "/models/1/thumbnail.png?size=" + "9" * 30,
    ],
)
def test_out_of_range_ints_elsewhere_are_422(served, path):
    client, _ = served
    assert client.get(path).status_code == 422


@pytest.mark.parametrize(
    "body",
    [
        {"seed": 99999999999999999999999},
        {"seed": 2**32},
        {"seed": -1},
        {"size": 10**30},
        {"size": 1},
        {"seed": 1.5},
    ],
)
def test_rebuild_payloads_out_of_range_are_422_and_queue_nothing(served, body):
    client, data = served
    before = snapshot(data)
    r = client.post("/admin/vocabulary/rebuild", json=body, headers=ADMIN)
    assert r.status_code == 422, r.text[:200]
    assert snapshot(data).jobs == before.jobs


def test_a_seed_in_range_is_accepted(served):
    client, _ = served
    r = client.post("/admin/vocabulary/rebuild", json={"size": 8, "seed": 2**32 - 1}, headers=ADMIN)
    assert r.status_code == 202


def test_duplicate_multipart_fields_are_422_and_store_nothing(served):
    client, data = served
    s = trimesh.creation.icosphere(subdivisions=2)
    good = obj_text(s.vertices * [1.0, 1.21, 0.93], s.faces)
    before = snapshot(data)
    wrong = []
    for case, body in duplicate_field_bodies(BOUNDARY, good):
        for route in ("/models", "/search"):
            r = client.post(route, content=body, headers=MULTIPART_HEADERS)
            if r.status_code != 422 or "more than once" not in r.json()["error"]["message"]:
                wrong.append(f"{route} {case}: {r.status_code} {r.text[:160]}")
    assert not wrong, "\n".join(wrong)
    assert snapshot(data) == before
