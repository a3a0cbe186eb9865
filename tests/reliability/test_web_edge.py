"""The web edge (issue 34): security headers on every response, 403 for a state change sent by another
site's page, startup refused for short tokens or an open dev mode on the network, 405 with Allow, and an
OpenAPI schema that lists every route with the server's own enums and limits."""

from __future__ import annotations

import base64
import hashlib
import re

import pytest
from fastapi.testclient import TestClient

from app.api import limits
from app.config import MIN_TOKEN_CHARS, is_loopback
from app.main import create_app
from app.services import catalog, metadata
from tests.api.live import live_server
from tests.api.test_web_browser import VIEWPORT, launch, needs_chromium
from tests.conftest import make_settings
from tests.reliability.corpus import valid_bytes
from tests.reliability.helpers import MULTIPART_HEADERS, multipart, snapshot

LONG = "x" * MIN_TOKEN_CHARS


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = make_settings(
        tmp_path_factory.mktemp("edge") / "data", workers=0, cors_origins=["https://ok.example"]
    )
    with TestClient(create_app(settings)) as c:
        yield c


def _has_security_headers(r) -> None:
    h = r.headers
    assert h["x-content-type-options"] == "nosniff", r.request.url
    assert h["x-frame-options"] == "DENY"
    assert h["referrer-policy"] == "no-referrer"
    csp = h["content-security-policy"]
    assert "frame-ancestors 'none'" in csp and "object-src 'none'" in csp
    script = re.search(r"script-src ([^;]*)", csp)
    assert script and "'unsafe-inline'" not in script.group(1) and "'unsafe-eval'" not in script.group(1)


def test_every_kind_of_response_carries_the_security_headers(client):
    answers = [
        client.get("/"),
        client.get("/static/app.js"),
        client.get("/static/vendor/three.min.js"),
        client.get("/docs"),
        client.get("/openapi.json"),
        client.get("/healthz"),
        client.get("/models/999"),  # 404
        client.put("/models"),  # 405
        client.get("/models?limit=0"),  # 422 from validation
        client.post("/search", content=b"not multipart", headers={"content-type": "text/plain"}),
        client.post(
            "/models", content=b"x", headers={**MULTIPART_HEADERS, "content-encoding": "gzip"}
        ),  # 415
        client.post("/models", headers={"origin": "https://evil.example"}),  # 403
    ]
    assert [r.status_code for r in answers][6:] == [404, 405, 422, 422, 415, 403]
    for r in answers:
        _has_security_headers(r)


def test_the_page_runs_only_its_own_scripts_and_docs_admits_its_one_inline_script_by_hash(client):
    page = client.get("/")
    assert "<script>" not in page.text  # no inline script: script-src 'self' is enough
    assert "script-src 'self';" in page.headers["content-security-policy"]
    docs = client.get("/docs")
    inline = re.findall(r"<script>(.*?)</script>", docs.text, re.S)
    assert len(inline) == 1
    digest = base64.b64encode(hashlib.sha256(inline[0].encode()).digest()).decode()
    assert f"'sha256-{digest}'" in docs.headers["content-security-policy"]
    assert "blob:" in page.headers["content-security-policy"]  # the query thumbnail is a blob: URL


def test_a_foreign_origin_cannot_change_state_but_same_origin_and_plain_clients_can(client, tmp_path):
    data = client.app.state.settings.data_dir
    before = snapshot(data)
    body = multipart("sphere.obj", valid_bytes("obj"))
    for origin in (
        "https://evil.example",
        "http://testserver.evil.example",
        "null",
        "http://eviltestserver",
    ):
        headers = {**MULTIPART_HEADERS, "origin": origin}
        r = client.post("/models", content=body, headers=headers)
        assert r.status_code == 403 and r.json()["error"]["code"] == "cross_origin", (origin, r.text)
        assert client.delete("/models/1", headers={"origin": origin}).status_code == 403
        assert client.post("/search", content=body, headers=headers).status_code == 403
    assert snapshot(data) == before
    # reading stays open to any page (CORS decides what the page may read)
    assert client.get("/models", headers={"origin": "https://evil.example"}).status_code == 200
    # the service's own page, an allowed origin, and clients that send no Origin
    for extra in (
        {"origin": "http://testserver"},
        {"origin": "http://TESTSERVER:80"},
        {"origin": "https://testserver:8080"},  # a proxy forwards Host without the port
        {"origin": "https://ok.example"},
        {},
    ):
        r = client.post("/models", content=body, headers={**MULTIPART_HEADERS, **extra})
        assert r.status_code in (200, 202), (extra, r.text)


def test_a_405_says_which_methods_are_allowed(client):
    r = client.put("/models")
    assert r.status_code == 405 and set(r.headers["allow"].replace(" ", "").split(",")) == {"GET", "POST"}
    assert r.json()["error"]["code"] == "method_not_allowed"
    r = client.post("/models/1/mesh")
    assert r.status_code == 405 and r.headers["allow"] == "GET"


@pytest.mark.parametrize(
    ("overrides", "words"),
    [
        ({"dev_mode": False, "admin_token": "s3cret"}, "SHAPEBAG_ADMIN_TOKEN is 6 characters long"),
        ({"dev_mode": True, "admin_token": "x" * (MIN_TOKEN_CHARS - 1)}, f"use at least {MIN_TOKEN_CHARS}"),
        (
            {"dev_mode": False, "admin_token": LONG, "api_token": "short-api-token"},
            "SHAPEBAG_API_TOKEN is 15",
        ),
        ({"dev_mode": True, "admin_token": "change-me", "host": "0.0.0.0"}, "loopback"),
        ({"dev_mode": True, "admin_token": "change-me", "host": "192.168.1.10"}, "not '192.168.1.10'"),
        ({"dev_mode": True, "admin_token": LONG, "host": ""}, "loopback"),
    ],
)
def test_startup_refuses_short_tokens_and_dev_mode_off_loopback(tmp_path, overrides, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        create_app(make_settings(tmp_path / "d", **overrides))


def test_startup_accepts_long_tokens_anywhere_and_dev_mode_on_loopback(tmp_path):
    create_app(
        make_settings(tmp_path / "a", dev_mode=False, admin_token=LONG, api_token=LONG, host="0.0.0.0")
    )
    for host in ("127.0.0.1", "localhost", "::1", "127.0.0.2"):
        create_app(make_settings(tmp_path / "b", dev_mode=True, admin_token="change-me", host=host))
    assert not is_loopback("0.0.0.0") and not is_loopback("::") and not is_loopback("example.org")


def test_the_schema_lists_every_route_with_the_server_enums_and_limits(client):
    schema = client.get("/openapi.json").json()
    paths = schema["paths"]
    preview = paths["/web/preview.png"]["post"]
    assert "image/png" in preview["responses"]["200"]["content"]
    assert preview["requestBody"]["content"]["multipart/form-data"]["schema"]["required"] == ["file"]
    for method, path in (("post", "/models"), ("delete", "/models/{model_id}"), ("post", "/search")):
        assert "403" in paths[path][method]["responses"], (method, path)
    for path in ("/models", "/admin/vocabulary/rebuild", "/admin/index/rebuild"):
        assert "507" in paths[path]["post"]["responses"], path
    assert "403" not in paths["/models"]["get"]["responses"]
    status = next(p for p in paths["/models"]["get"]["parameters"] if p["name"] == "status")
    assert status["schema"]["anyOf"][0]["enum"] == list(catalog.STATUSES)
    form = paths["/models"]["post"]["requestBody"]["content"]["multipart/form-data"]["schema"]["properties"]
    assert form["name"]["maxLength"] == limits.MAX_TEXT_CHARS
    assert form["metadata"]["maxLength"] == metadata.MAX_METADATA_BYTES
    against = paths["/explain"]["post"]["requestBody"]["content"]["multipart/form-data"]["schema"]
    assert against["properties"]["against"]["minimum"] == 1
    # every route the app serves, less the page and its assets, is documented
    served = {(m, r.path) for r in client.app.routes for m in getattr(r, "methods", ()) if m != "HEAD"}
    documented = {(m.upper(), p) for p, ops in paths.items() for m in ops}
    hidden = {p for _, p in served - documented}
    assert hidden <= {
        "/",
        "/static/{name}",
        "/docs",
        "/docs/oauth2-redirect",
        "/static/vendor/{name}",
        "/openapi.json",
    }
    # the server enforces the enum the schema states
    r = client.get("/models?status=deleted")
    assert r.status_code == 422 and "queued" in r.json()["error"]["message"]


def test_shapebag_serve_in_dev_mode_on_every_address_exits_with_one_line(tmp_path, capsys, monkeypatch):
    from app.cli import main as cli_main

    monkeypatch.delenv("SHAPEBAG_ADMIN_TOKEN", raising=False)
    code = cli_main(
        ["serve", "--dev", "--host", "0.0.0.0", "--data-dir", str(tmp_path / "d"), "--workers", "0"]
    )
    lines = [
        ln for ln in capsys.readouterr().err.strip().splitlines() if not ln.startswith("data directory: ")
    ]
    assert code == 2 and len(lines) == 1 and "loopback" in lines[0], lines


@needs_chromium
def test_the_page_and_docs_run_under_their_policy_without_a_violation(tmp_path):
    """Chromium reports every resource or script the policy blocks (securitypolicyviolation events and
    console errors): the page and /docs with Swagger UI report none (the viewer test runs three.js under
    the same policy)."""
    from playwright.sync_api import sync_playwright

    watch = (
        "window.__csp = []; document.addEventListener('securitypolicyviolation',"
        " e => window.__csp.push(e.violatedDirective + ' ' + e.blockedURI));"
    )
    with live_server(make_settings(tmp_path / "data", workers=0)) as base, sync_playwright() as p:
        browser = launch(p)
        page = browser.new_page(viewport=VIEWPORT)
        page.add_init_script(watch)
        console: list[str] = []
        page.on("console", lambda m: console.append(m.text) if "Content Security Policy" in m.text else None)
        page.goto(base + "/")
        page.wait_for_selector("#status")
        page.wait_for_load_state("networkidle")
        on_page = page.evaluate("window.__csp")
        page.goto(base + "/docs")
        page.wait_for_selector(".swagger-ui .opblock", timeout=30_000)
        on_docs = page.evaluate("window.__csp")
        # the watch does see what the policy blocks: an inline script injected into the docs page
        page.evaluate(
            "() => document.body.append(Object.assign(document.createElement('script'), {text: '1'}))"
        )
        page.wait_for_timeout(300)
        injected = page.evaluate("window.__csp")
        browser.close()
    assert on_page == [] and on_docs == [], (on_page, on_docs)
    assert len(injected) == 1 and injected[0].startswith("script-src"), injected
    assert len(console) == 1, console  # the injected script's report, nothing else
