"""/docs works with no network (issue 14 item 3): Swagger UI comes from the package, never a CDN."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from tests.conftest import make_settings


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> TestClient:
    # no `with`: the lifespan (workers, index) is not needed to serve the docs
    return TestClient(create_app(make_settings(tmp_path_factory.mktemp("d") / "data")))


def test_docs_reference_only_same_origin_assets_and_they_are_served(client: TestClient) -> None:
    r = client.get("/docs")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    refs = re.findall(r"""(?:src|href)\s*=\s*["']([^"']+)["']""", r.text)
    urls = re.findall(r"""url:\s*['"]([^'"]+)['"]""", r.text)
    assert "/static/vendor/swagger-ui-bundle.js" in refs and "/static/vendor/swagger-ui.css" in refs
    assert "/openapi.json" in urls
    for ref in refs + urls:
        assert ref.startswith("/") and not ref.startswith("//"), f"{ref}: not same-origin"
        asset = client.get(ref)
        assert asset.status_code == 200 and len(asset.content) > 0, ref
    assert "http:" not in r.text and "https:" not in r.text  # no absolute URL at all: nothing off-site


def test_vendored_assets_have_the_right_types_and_licences(client: TestClient) -> None:
    js = client.get("/static/vendor/swagger-ui-bundle.js")
    assert js.headers["content-type"].startswith("text/javascript") and b"SwaggerUIBundle" in js.content
    assert client.get("/static/vendor/swagger-ui.css").headers["content-type"].startswith("text/css")
    three = client.get("/static/vendor/three.min.js")
    assert three.headers["content-type"].startswith("text/javascript") and b"OrbitControls" in three.content
    vendor = Path(__file__).resolve().parents[2] / "app" / "api" / "static" / "vendor"
    assert (vendor / "three.LICENSE").is_file() and (vendor / "swagger-ui.LICENSE").is_file()


@pytest.mark.parametrize(
    "name", ["update.sh", "three.LICENSE", "nope.js", "..%2F..%2Fapp.js", "%2Fetc%2Fpasswd"]
)
def test_only_listed_vendor_assets_are_served(client: TestClient, name: str) -> None:
    r = client.get(f"/static/vendor/{name}")
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"


def test_redoc_is_off_rather_than_blank(client: TestClient) -> None:
    assert client.get("/redoc").status_code == 404
    assert client.get("/docs/oauth2-redirect").status_code == 200
