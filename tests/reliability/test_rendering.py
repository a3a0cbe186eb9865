"""Previews and thumbnails (issue 12, items 4 and 5): decoded and rendered in a query-pool process, never
in the API process; thumbnails only at a few fixed sizes, so the cache is bounded per model."""

from __future__ import annotations

import shutil

import pytest
import trimesh
from fastapi.testclient import TestClient

from app.main import create_app
from app.services import catalog, mesh_policy, rendering
from tests.conftest import make_settings, wait_for
from tests.reliability.corpus import obj_text


@pytest.fixture(scope="module")
def served(seeded_dir, tmp_path_factory):
    data = shutil.copytree(seeded_dir, tmp_path_factory.mktemp("render") / "data")
    with TestClient(create_app(make_settings(data, search_processes=2))) as client:
        wait_for(lambda: client.get("/readyz").status_code == 200, timeout_s=60)
        yield client, data


def _no_decoding_here(monkeypatch) -> None:
    """Any mesh decode in this (the API) process fails the request; the pool's processes are spawned
    fresh interpreters, which these patches do not reach."""

    def refuse(*args, **kwargs):
        raise AssertionError("a mesh was decoded in the API process")

    for module, name in ((rendering, "load_mesh"), (rendering, "load_upload"), (mesh_policy, "load_mesh")):
        monkeypatch.setattr(module, name, refuse)


def test_the_preview_is_decoded_and_rendered_outside_the_api_process(served, monkeypatch):
    client, _ = served
    _no_decoding_here(monkeypatch)
    s = trimesh.creation.icosphere(subdivisions=2)
    r = client.post("/web/preview.png", files={"file": ("ball.obj", obj_text(s.vertices, s.faces))})
    assert r.status_code == 200 and r.headers["content-type"] == "image/png", r.text[:300]


def test_thumbnails_render_outside_the_api_process_at_fixed_sizes_only(served, monkeypatch):
    client, data = served
    _no_decoding_here(monkeypatch)
    model_id = client.get("/models", params={"status": "ready", "limit": 1}).json()["data"][0]["id"]
    for size in (8, 32, 64, 100, 255, 257, 300, 1000, 1024, 2048):
        r = client.get(f"/models/{model_id}/thumbnail.png", params={"size": size})
        assert r.status_code == 422 and "128, 256, 512" in r.json()["error"]["message"], (size, r.text)
    for size in rendering.THUMBNAIL_SIZES:
        r = client.get(f"/models/{model_id}/thumbnail.png", params={"size": size})
        assert r.status_code == 200 and r.headers["content-type"] == "image/png", (size, r.text[:200])
    assert client.get(f"/models/{model_id}/thumbnail.png").status_code == 200  # default size
    cached = sorted(p.name for p in (data / "thumbnails").glob(f"{model_id}-*.png"))
    assert cached == sorted(f"{model_id}-{s}.png" for s in rendering.THUMBNAIL_SIZES)


def test_a_thumbnail_of_a_missing_model_is_404(served):
    client, _ = served
    assert client.get("/models/999999/thumbnail.png").status_code == 404


def test_a_model_deleted_while_its_thumbnail_renders_leaves_no_file(served, monkeypatch):
    client, data = served
    runtime = client.app.state.runtime
    ready = client.get("/models", params={"status": "ready", "limit": 50}).json()["data"]
    model_id = ready[-1]["id"]  # not the one the other test rendered (its thumbnails are cached)
    # the ingest kept the results page's size (256); 128 is rendered on this first view
    assert not (data / "thumbnails" / f"{model_id}-128.png").exists()
    real_run = runtime.describer.run

    async def render_then_delete(*args, **kwargs):
        png = await real_run(*args, **kwargs)
        catalog.delete_model(runtime.ctx, runtime.live, model_id)  # lands between render and write
        return png

    monkeypatch.setattr(runtime.describer, "run", render_then_delete)
    r = client.get(f"/models/{model_id}/thumbnail.png", params={"size": 128})
    assert r.status_code == 404
    assert not list((data / "thumbnails").glob(f"{model_id}-*.png"))
