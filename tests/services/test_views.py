"""What a model needs to be viewed is computed once and kept (issue 34): the explain geometry and the
results page's thumbnail at ingest (else on first use), other thumbnail sizes on first use; a failure is
kept too and answered at once (a placeholder image, or a 422 naming the reason), never computed again
per view. Pool calls are counted by wrapping the runtime's pool; the work itself runs in real pool
processes."""

from __future__ import annotations

import asyncio
import io
import shutil

import numpy as np
import pytest
import trimesh
from fastapi.testclient import TestClient
from PIL import Image

from app.core.mesh import Mesh, load_mesh
from app.core.pipeline import canonical_mesh
from app.main import create_app
from app.services import catalog, ingestion, views
from app.services.errors import PoolBusyError
from app.services.explain import from_canonical
from app.services.thumbnails import RenderTooCostlyError, render_rgba
from tests.conftest import make_settings, wait_for
from tests.reliability.corpus import obj_text


@pytest.fixture(scope="module")
def served(seeded_dir, tmp_path_factory):
    data = shutil.copytree(seeded_dir, tmp_path_factory.mktemp("views") / "data")
    with TestClient(create_app(make_settings(data, workers=0))) as client:
        wait_for(lambda: client.get("/models", params={"status": "ready"}).json()["count"] > 0)
        yield client, data


@pytest.fixture
def pool_calls(served, monkeypatch):
    """The kinds of work sent to the pool during the test."""
    client, _ = served
    pool = client.app.state.runtime.describer
    calls: list[str] = []
    real = pool.run

    async def counted(fn, args, what, timeout_s=None, kind="describe"):
        calls.append(kind)
        return await real(fn, args, what, timeout_s, kind=kind)

    monkeypatch.setattr(pool, "run", counted)
    return calls


def _ready(client, n: int = 0) -> dict:
    return client.get("/models", params={"status": "ready", "limit": 50}).json()["data"][n]


def test_the_geometry_kept_at_ingest_is_the_one_explain_shows_and_no_pool_runs(served, pool_calls):
    client, data = served
    model = _ready(client)
    kept = data / "views" / f"{model['id']}.{views.GEOMETRY}"
    assert kept.is_file()
    r = client.get(f"/models/{model['id']}/explain")
    assert r.status_code == 200, r.text
    assert pool_calls == []  # nothing decoded or resampled per view
    # the kept geometry is what the pool would compute from the stored mesh now
    ctx = client.app.state.runtime.ctx
    record = catalog.get_model(ctx, model["id"])
    mesh = load_mesh(ctx.blobs.mesh_path(record.sha256, record.file_type).read_bytes(), record.file_type)
    fresh = from_canonical(canonical_mesh(mesh, ctx.settings.describe.params()))
    shape = r.json()["shape"]
    np.testing.assert_allclose(np.reshape(shape["vertices"], (-1, 3)), fresh.vertices, atol=2e-5)
    assert np.array_equal(np.reshape(shape["faces"], (-1, 3)), fresh.faces)


def test_a_model_ingested_before_gets_its_geometry_computed_once_on_first_view(served, pool_calls):
    client, data = served
    model = _ready(client, 1)
    kept = data / "views" / f"{model['id']}.{views.GEOMETRY}"
    kept.unlink()  # as a model ingested before geometry was kept
    first = client.get(f"/models/{model['id']}/explain")
    assert first.status_code == 200 and pool_calls == ["explain"]
    assert kept.is_file()
    second = client.get(f"/models/{model['id']}/explain")
    assert second.json() == first.json() and pool_calls == ["explain"]  # not again


def test_a_geometry_failure_is_kept_and_answered_at_once(served, pool_calls):
    client, data = served
    model = _ready(client, 2)
    ctx = client.app.state.runtime.ctx
    record = catalog.get_model(ctx, model["id"])
    (data / "views" / f"{model['id']}.{views.GEOMETRY}").unlink()
    mesh_path = ctx.blobs.mesh_path(record.sha256, record.file_type)
    original = mesh_path.read_bytes()
    mesh_path.write_bytes(b"not a mesh at all\n")  # the stored mesh no longer decodes
    try:
        first = client.get(f"/models/{model['id']}/explain")
        assert first.status_code == 422 and "cannot be explained" in first.json()["error"]["message"]
        assert pool_calls == ["explain"]
        mesh_path.write_bytes(original)  # even with the mesh back, the kept failure answers
        again = client.get(f"/models/{model['id']}/explain")
        assert again.status_code == 422 and again.json() == first.json()
        assert pool_calls == ["explain"]
    finally:
        mesh_path.write_bytes(original)


def test_a_thumbnail_that_cannot_be_rendered_is_a_kept_placeholder(served, pool_calls):
    client, data = served
    ctx = client.app.state.runtime.ctx
    dust = np.random.default_rng(3).normal(size=(30, 3))  # a point cloud: stored, never renderable
    submitted = ingestion.submit(ctx, obj_text(dust, None), "dust.obj")
    model_id = submitted.model.id
    for size in (128, 128, 256):
        r = client.get(f"/models/{model_id}/thumbnail.png", params={"size": size})
        assert r.status_code == 200 and r.headers["content-type"] == "image/png"
        assert r.headers[views.PLACEHOLDER_HEADER] and r.headers["cache-control"] == "no-cache"
        assert Image.open(io.BytesIO(r.content)).size == (size, size)
    assert pool_calls == ["render", "render"]  # once per size, never per view
    assert (data / "views" / f"{model_id}.thumbnail-128.failed").is_file()
    catalog.delete_model(ctx, client.app.state.runtime.live, model_id)  # its kept failures go with it
    assert not list((data / "views").glob(f"{model_id}.*"))


def test_a_rendered_thumbnail_is_kept_and_deleted_with_its_model(served, pool_calls):
    client, data = served
    model = _ready(client, 3)
    for _ in range(3):
        r = client.get(f"/models/{model['id']}/thumbnail.png", params={"size": 128})
        assert r.status_code == 200 and views.PLACEHOLDER_HEADER not in r.headers
    assert pool_calls == ["render"]
    catalog.delete_model(client.app.state.runtime.ctx, client.app.state.runtime.live, model["id"])
    assert not list((data / "views").glob(f"{model['id']}.*"))
    assert not list((data / "thumbnails").glob(f"{model['id']}-*"))


def test_the_results_pages_thumbnail_is_rendered_at_ingest(served, pool_calls):
    client, data = served
    model = _ready(client, 4)
    kept = data / "thumbnails"
    assert list(kept.glob(f"{model['id']}-*")), "no thumbnail kept by the ingest"
    r = client.get(f"/models/{model['id']}/thumbnail.png")  # the page's size
    assert r.status_code == 200 and views.PLACEHOLDER_HEADER not in r.headers
    assert Image.open(io.BytesIO(r.content)).size == (256, 256)
    assert pool_calls == []  # read from disk: a first Browse waits on no render


def test_a_thumbnail_that_fails_at_ingest_is_kept_as_a_failure(served):
    client, data = served
    ctx = client.app.state.runtime.ctx
    slivers = _slivers_across_the_frame()
    model_id = ingestion.submit(ctx, obj_text(slivers.vertices, slivers.faces), "slivers.obj").model.id
    views.save_thumbnail(ctx, model_id, slivers)  # as the ingest does: refused by the renderer's budget
    failed = data / "views" / f"{model_id}.thumbnail-256.failed"
    assert failed.is_file() and "cannot be rendered" in failed.read_text()
    assert not (data / "thumbnails" / f"{model_id}-256.png").exists()
    r = client.get(f"/models/{model_id}/thumbnail.png")
    assert r.status_code == 200 and "cannot be rendered" in r.headers[views.PLACEHOLDER_HEADER]
    catalog.delete_model(ctx, client.app.state.runtime.live, model_id)


def _slivers_across_the_frame(n: int = 20_000) -> Mesh:
    a = np.random.default_rng(0).normal(size=(n, 3)) * 1e-3
    v = np.concatenate([a, a + [1.0, 1.0, 0.3], a + [1.0001, 1.0, 0.3]])
    return Mesh(v, np.arange(3 * n).reshape(3, n).T)


def test_concurrent_first_views_share_one_computation(served):
    client, _ = served
    pool = client.app.state.runtime.describer
    runs = []

    async def scenario():
        async def make():
            runs.append(1)
            await asyncio.sleep(0.2)
            return len(runs)

        return await asyncio.gather(*(pool.shared(("k", 1), make) for _ in range(5)))

    assert asyncio.run(scenario()) == [1] * 5 and runs == [1]


def test_a_needle_renders_and_slivers_across_the_frame_are_refused_before_the_work():
    needle = trimesh.creation.box(extents=(1e6, 1.0, 1.0))  # 1e6:1: once a 500 on every view
    image = render_rgba(needle.vertices, needle.faces, 128)
    assert image.shape == (128, 128, 4)
    n = 20_000
    rng = np.random.default_rng(0)
    a = rng.normal(size=(n, 3)) * 1e-3
    v = np.concatenate([a, a + [1.0, 1.0, 0.3], a + [1.0001, 1.0, 0.3]])
    f = np.arange(3 * n).reshape(3, n).T
    with pytest.raises(RenderTooCostlyError, match="candidate pixels"):
        render_rgba(v, f, 256)
    cube = trimesh.creation.box()  # a few frame-sized triangles are well inside the budget
    assert render_rgba(cube.vertices, cube.faces, 512)[..., 3].max() == 255


def test_a_busy_pool_is_not_kept_as_the_models_failure(served, monkeypatch):
    client, data = served
    model = _ready(client, 4)
    pool = client.app.state.runtime.describer
    real = pool.run

    async def busy(*args, **kwargs):
        raise PoolBusyError("rendering the thumbnail: no process was free within 20 s; retry shortly")

    monkeypatch.setattr(pool, "run", busy)
    r = client.get(f"/models/{model['id']}/thumbnail.png", params={"size": 128})
    assert r.status_code == 503 and "retry-after" in r.headers
    assert not list((data / "views").glob(f"{model['id']}.*.failed"))
    monkeypatch.setattr(pool, "run", real)
    again = client.get(f"/models/{model['id']}/thumbnail.png", params={"size": 128})
    assert again.status_code == 200 and views.PLACEHOLDER_HEADER not in again.headers


def _ribbon(n: int, width: float, length: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A strip one triangle wide: (2n + 2, 3) vertices, (2n, 3) faces."""
    x = np.linspace(0.0, length, n + 1)
    v = np.concatenate([np.stack([x, 0 * x, 0 * x], 1), np.stack([x, 0 * x + width, 0 * x], 1)])
    i = np.arange(n)
    f = np.concatenate([np.stack([i, i + 1, n + 1 + i], 1), np.stack([i + 1, n + 2 + i, n + 1 + i], 1)])
    return v, f


def test_previews_of_a_ribbon_and_of_slivers_are_never_a_500(served):
    client, _ = served
    v, f = _ribbon(10_000, 0.01)  # 20,000 triangles: once a 500 (no pixel centre inside any)
    r = client.post("/web/preview.png", files={"file": ("ribbon.obj", obj_text(v, f))})
    assert r.status_code in (200, 422), r.text[:300]
    n = 4_000
    a = np.random.default_rng(1).normal(size=(n, 3)) * 1e-3
    slivers = np.concatenate([a, a + [1.0, 1.0, 0.3], a + [1.0001, 1.0, 0.3]])
    faces = np.arange(3 * n).reshape(3, n).T
    r = client.post("/web/preview.png", files={"file": ("slivers.obj", obj_text(slivers, faces))})
    assert r.status_code == 422, r.text[:300]
