"""The web page's routes: the page, its assets, and the query preview (no lifespan needed)."""

from __future__ import annotations

import io
import re
from collections.abc import Iterator
from types import SimpleNamespace

import pytest
import trimesh
from fastapi import FastAPI
from fastapi.testclient import TestClient
from PIL import Image

from app.api import errors
from app.api.routes import web
from app.config import Settings
from app.core.pipeline import DescribeParams
from app.services import rendering
from app.services.query_pool import QueryDescriber


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    app = FastAPI()
    data_dir = tmp_path_factory.mktemp("d")
    settings = Settings(data_dir=data_dir, dev_mode=True, max_upload_bytes=200_000)
    app.state.settings = settings
    # the preview renders in a query-pool process: the one piece of the runtime these routes use
    describer = QueryDescriber(1, DescribeParams(), settings.max_vertices, 60.0)
    app.state.runtime = SimpleNamespace(ctx=SimpleNamespace(settings=settings), describer=describer)
    errors.install(app)
    app.include_router(web.router)
    yield TestClient(app)
    describer.close()



def test_the_file_picker_and_its_hint_list_every_format_read(client: TestClient) -> None:
    from app.core.formats import READERS

    html = client.get("/").text
    (accept,) = re.findall(r'<input type="file" id="file"[^>]*accept="([^"]*)"', html)
    assert sorted(accept.split(",")) == sorted(f".{ext}" for ext in READERS)
    hint = re.search(r'<p class="drop-hint">([^<]*)', html).group(1)
    assert all(ext.upper() in hint for ext in READERS) and "{{" not in html


def test_search_help_lists_every_format_read(capsys) -> None:
    from app.cli import main
    from app.core.formats import READERS

    with pytest.raises(SystemExit):
        main(["search", "--help"])
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps the help
    assert all(ext in text for ext in READERS), text

def _obj(mesh: trimesh.Trimesh) -> bytes:
    return mesh.export(file_type="obj").encode()


def test_page_links_only_local_assets_that_exist(client: TestClient) -> None:
    r = client.get("/")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    refs = re.findall(r'(?:src|href)="([^"#]+)"', r.text)
    assert "/static/app.js" in refs and "/static/style.css" in refs
    for ref in refs:
        assert not ref.startswith(("http:", "https:", "//")), f"external reference {ref}: no CDN allowed"
        if ref.startswith("/static/"):
            asset = client.get(ref)
            assert asset.status_code == 200 and asset.content, ref
    assert client.get("/static/app.js").headers["content-type"].split(";")[0] in (
        "text/javascript", "application/javascript",
    )
    assert client.get("/static/style.css").headers["content-type"].startswith("text/css")


def test_page_script_uses_the_api_contract(client: TestClient) -> None:
    js = client.get("/static/app.js").text
    needles = ('"/search"', "/models?", "/similar?k=", "/thumbnail.png", "body.error.message",
               "/web/preview.png")
    for needle in needles:
        assert needle in js, needle


@pytest.mark.parametrize("name", ["nope.js", "..%2Fweb.py", "..%2F..%2Fconfig.py", "%2Fetc%2Fpasswd"])
def test_unknown_or_escaping_static_paths_are_404_json(client: TestClient, name: str) -> None:
    r = client.get(f"/static/{name}")
    assert r.status_code == 404
    assert r.json()["error"]["code"] == "not_found"


def test_preview_renders_the_uploaded_mesh(client: TestClient) -> None:
    data = _obj(trimesh.creation.icosphere(subdivisions=2))
    r = client.post("/web/preview.png", files={"file": ("ball.obj", data)})
    assert r.status_code == 200 and r.headers["content-type"] == "image/png"
    image = Image.open(io.BytesIO(r.content))
    assert image.size == (rendering.PREVIEW_SIZE, rendering.PREVIEW_SIZE)
    assert image.getchannel("A").getextrema() == (0, 255)  # something drawn on a transparent ground


@pytest.mark.parametrize(
    ("files", "status", "code"),
    [
        ({"file": ("junk.obj", b"this is not a mesh")}, 422, "invalid_mesh"),
        ({"file": ("model.xyz", b"v 0 0 0")}, 415, "unsupported_format"),
        ({"other": ("a.obj", b"v 0 0 0")}, 422, "invalid_input"),
        ({"file": ("big.obj", b"#" * 300_000)}, 413, "payload_too_large"),
    ],
)
def test_preview_bad_uploads_get_clear_json_errors(
    client: TestClient, files: dict, status: int, code: str
) -> None:
    r = client.post("/web/preview.png", files=files)
    assert r.status_code == status, r.text
    body = r.json()["error"]
    assert body["code"] == code and body["message"]
