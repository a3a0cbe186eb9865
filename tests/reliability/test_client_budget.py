"""The bound per client (issue 34): a client is its valid token, else its address; past its costly
requests in flight it gets 429 + Retry-After before its body is read, while other clients are served;
a ClientOverBudget from the budgets becomes the same 429."""

from __future__ import annotations

import asyncio
import time

import httpx
import pytest
from fastapi import FastAPI

from app.api.client_budget import ClientBudget, client_key, is_costly
from app.services.clients import ClientOverBudget, current_client

TOKENS = {"api": "a" * 40, "admin": "b" * 40}


def _scope(headers: dict[str, str], addr: str = "10.0.0.7") -> dict:
    return {
        "type": "http",
        "headers": [(k.lower().encode(), v.encode()) for k, v in headers.items()],
        "client": (addr, 5555),
    }


def test_a_client_is_its_valid_token_else_its_address():
    assert client_key(_scope({"Authorization": "Bearer " + "a" * 40}), TOKENS) == "token:api"
    assert client_key(_scope({"X-API-Token": "a" * 40}), TOKENS) == "token:api"
    assert client_key(_scope({"X-Admin-Token": "b" * 40}), TOKENS) == "token:admin"
    # a made-up token names no one: it cannot buy a fresh budget
    assert client_key(_scope({"Authorization": "Bearer made-up"}), TOKENS) == "addr:10.0.0.7"
    assert client_key(_scope({"X-API-Token": "a" * 39}), TOKENS) == "addr:10.0.0.7"
    assert client_key(_scope({}, addr="10.0.0.8"), TOKENS) == "addr:10.0.0.8"
    assert client_key(_scope({"X-API-Token": ""}), {"api": "", "admin": "b" * 40}) == "addr:10.0.0.7"


def test_costly_requests_are_the_pool_and_upload_ones():
    costly = [
        ("POST", "/search"),
        ("POST", "/models"),
        ("POST", "/explain"),
        ("POST", "/web/preview.png"),
        ("GET", "/models/3/explain"),
        ("GET", "/models/3/thumbnail.png"),
        ("GET", "/models/3/similar"),
    ]
    cheap = [
        ("GET", "/models"),
        ("GET", "/models/3"),
        ("GET", "/healthz"),
        ("DELETE", "/models/3"),
        ("GET", "/search"),
        ("GET", "/models/3/mesh"),
    ]
    assert all(is_costly({"method": m, "path": p}) for m, p in costly)
    assert not any(is_costly({"method": m, "path": p}) for m, p in cheap)


def _app(gate: asyncio.Event, seen: list[str]) -> FastAPI:
    app = FastAPI()

    @app.post("/search")
    async def search() -> dict:
        seen.append(current_client())
        await gate.wait()
        return {"ok": True}

    @app.post("/explain")
    async def explain() -> dict:
        raise ClientOverBudget("2 of your requests already wait for explaining")

    @app.get("/models")
    async def models() -> dict:
        return {"client": current_client()}

    app.add_middleware(ClientBudget, max_requests=2, tokens=TOKENS)
    return app


def test_past_its_requests_in_flight_a_client_gets_429_and_others_are_served():
    async def scenario():
        gate, seen = asyncio.Event(), []
        app = _app(gate, seen)
        flooder = httpx.AsyncClient(
            transport=httpx.ASGITransport(app, client=("10.0.0.1", 1)), base_url="http://t"
        )
        normal = httpx.AsyncClient(
            transport=httpx.ASGITransport(app, client=("10.0.0.2", 1)), base_url="http://t"
        )
        held = [asyncio.ensure_future(flooder.post("/search", content=b"x")) for _ in range(2)]
        while len(seen) < 2:
            await asyncio.sleep(0.01)
        refused = await flooder.post("/search", content=b"x" * 1000)
        assert refused.status_code == 429 and refused.json()["error"]["code"] == "too_many_requests"
        assert int(refused.headers["retry-after"]) > 0
        assert (await flooder.get("/models")).json() == {"client": "addr:10.0.0.1"}  # cheap: never bounded
        other = asyncio.ensure_future(normal.post("/search", content=b"x"))  # another client: let in
        while len(seen) < 3:
            await asyncio.sleep(0.01)
        gate.set()
        assert [r.status_code for r in await asyncio.gather(*held, other)] == [200, 200, 200]
        assert seen == ["addr:10.0.0.1", "addr:10.0.0.1", "addr:10.0.0.2"]
        assert (await flooder.post("/search", content=b"x")).status_code == 200  # its slots came back
        over = await normal.post("/explain", content=b"x")  # a budget's own refusal, the same answer
        assert over.status_code == 429 and "already wait" in over.json()["error"]["message"]
        assert "retry-after" in over.headers
        await flooder.aclose()
        await normal.aclose()

    asyncio.run(scenario())


def test_an_upload_records_its_client_on_the_ingest_job(settings, corpus):
    from fastapi.testclient import TestClient

    from app.main import create_app
    from app.storage import jobs as jobs_repo
    from tests.conftest import make_settings

    token = "t" * 40
    app = create_app(make_settings(settings.data_dir, workers=0, api_token=token))
    (first, _), (second, _) = corpus.files[0], corpus.files[1]
    with TestClient(app) as client:
        with_token = client.post(
            "/models", files={"file": (first.name, first.read_bytes())}, headers={"X-API-Token": token}
        )
        assert with_token.status_code == 202, with_token.text
        admin = client.post(
            "/models",
            files={"file": (second.name, second.read_bytes())},
            headers={"Authorization": f"Bearer {settings.admin_token}"},
        )
        assert admin.status_code == 202, admin.text
        ctx = app.state.runtime.ctx
        with ctx.db.read() as conn:
            jobs = [jobs_repo.get(conn, r.json()["job_id"]) for r in (with_token, admin)]
    assert [j.client for j in jobs] == ["token:api", "token:admin"]  # type: ignore[union-attr]


@pytest.mark.slow
def test_a_real_server_answers_a_client_over_its_queue_share_with_429(data_dir, corpus, tmp_path):
    """Through every middleware of the real app: one process, a queue of 2 (a client may hold 1 of it),
    slow describes; four searches at once from one address: 1 runs, 1 waits, 2 are 429."""
    from concurrent.futures import ThreadPoolExecutor

    from tests.reliability.helpers import MULTIPART_HEADERS, multipart, start_server

    server, base = start_server(
        data_dir,
        tmp_path / "s.log",
        SHAPEBAG_WORKERS="0",
        SHAPEBAG_POOL_PROCESSES="1",
        SHAPEBAG_SEARCH_PROCESSES="1",
        SHAPEBAG_SEARCH_QUEUE="2",
        SHAPEBAG_DESCRIBE__K="200",
        SHAPEBAG_DESCRIBE__TARGET_VERTICES="6000",  # a solve of seconds: the four overlap
    )
    path, _ = corpus.held_out[0]
    body = multipart(path.name, path.read_bytes())
    try:
        with httpx.Client(base_url=base, timeout=120) as http, ThreadPoolExecutor(4) as pool:
            answers = list(
                pool.map(
                    lambda _: http.post("/search", content=body, headers=MULTIPART_HEADERS), range(4)
                )
            )
    finally:
        server.stop()
    codes = sorted(r.status_code for r in answers)
    refused = [r for r in answers if r.status_code == 429]
    assert codes == [200, 200, 429, 429], [r.text[:200] for r in answers]
    assert all(r.json()["error"]["code"] == "too_many_requests" and r.headers["retry-after"] for r in refused)
    assert all("already wait" in r.json()["error"]["message"] for r in refused)


def test_the_schema_lists_the_429_on_every_costly_operation_only(settings):
    from fastapi.testclient import TestClient

    from app.main import create_app

    with TestClient(create_app(settings)) as client:
        paths = client.get("/openapi.json").json()["paths"]
    costly = [
        ("/search", "post"),
        ("/models", "post"),
        ("/explain", "post"),
        ("/models/{model_id}/explain", "get"),
        ("/models/{model_id}/thumbnail.png", "get"),
        ("/models/{model_id}/similar", "get"),
    ]
    for path, method in costly:
        answer = paths[path][method]["responses"]["429"]
        assert "Retry-After" in answer["headers"], (path, method)
    assert "429" not in paths["/models"]["get"]["responses"]
    assert "429" not in paths["/models/{model_id}"]["get"]["responses"]


@pytest.mark.parametrize("trusted", ["", "127.0.0.1"])
def test_behind_a_named_proxy_each_forwarded_address_is_its_own_client(data_dir, tmp_path, trusted):
    """SHAPEBAG_CLIENT_REQUESTS=1, one costly request held open (a body half sent) for X-Forwarded-For
    10.0.0.1. With the proxy named (127.0.0.1), 10.0.0.2 is another client and is served while the
    same 10.0.0.1 is 429; with none named, the header is ignored: everyone is 127.0.0.1, and 429."""
    import socket

    from tests.reliability.helpers import start_server

    server, base = start_server(data_dir, tmp_path / "s.log", SHAPEBAG_WORKERS="0",
                                SHAPEBAG_CLIENT_REQUESTS="1", SHAPEBAG_FORWARDED_ALLOW_IPS=trusted)
    try:
        port = int(base.rsplit(":", 1)[1])
        held = socket.create_connection(("127.0.0.1", port), timeout=30)
        held.sendall(b"POST /search HTTP/1.1\r\nHost: x\r\nX-Forwarded-For: 10.0.0.1\r\n"
                     b"Content-Type: multipart/form-data; boundary=B\r\nContent-Length: 1000\r\n\r\n--B\r\n")
        time.sleep(0.5)  # its request is in flight, its body half read
        bad = b"not multipart"
        with httpx.Client(base_url=base, timeout=30) as http:
            other = http.post("/search", content=bad, headers={"X-Forwarded-For": "10.0.0.2"})
            same = http.post("/search", content=bad, headers={"X-Forwarded-For": "10.0.0.1"})
        held.close()
    finally:
        server.stop()
    assert same.status_code == 429
    if trusted:
        assert other.status_code == 422, other.text[:200]  # its own client: served (a clear 422)
    else:
        assert other.status_code == 429  # the header names no one: one client, over its bound
