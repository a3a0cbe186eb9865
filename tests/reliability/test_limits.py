"""Limits that bound what one request can cost: the byte limit while streaming, the job queue (503 +
Retry-After), and the describe time limit (504 in time, no process left running)."""

from __future__ import annotations

import select
import socket
import threading
import time
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from tests.conftest import make_settings, wait_for
from tests.reliability.helpers import MULTIPART_HEADERS, descendants, multipart, start_server

LIMIT = 1_000_000


def _send_until_answered(port: int, total: int, chunk: int = 64 * 1024) -> tuple[int, bytes]:
    """POST a chunked multipart body of `total` bytes, stopping as soon as the server answers.
    Returns (bytes sent, response head)."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=30)
    head = (
        "POST /models HTTP/1.1\r\nHost: 127.0.0.1\r\nTransfer-Encoding: chunked\r\n"
        f"Content-Type: {MULTIPART_HEADERS['content-type']}\r\n\r\n"
    ).encode()
    sock.sendall(head)
    body_start = multipart("huge.obj", b"")[: -len(b"\r\n--reliability-boundary-7f3a--\r\n")]
    sent = 0
    piece = b"v 0 0 0\n" * (chunk // 8)
    try:
        payload = body_start
        while sent < total:
            frame = f"{len(payload):x}\r\n".encode() + payload + b"\r\n"
            sock.sendall(frame)
            sent += len(payload)
            payload = piece
            readable, _, _ = select.select([sock], [], [], 0)
            if readable:
                break
        sock.settimeout(30)
        answer = sock.recv(4096)
        while b"}" not in answer and (more := sock.recv(4096)):  # the body may come in its own packet
            answer += more
    except (BrokenPipeError, ConnectionResetError):
        answer = sock.recv(4096) if select.select([sock], [], [], 5)[0] else b""
    finally:
        sock.close()
    return sent, answer


@pytest.mark.slow
def test_an_oversized_upload_is_refused_while_streaming(tmp_path):
    server, base = start_server(
        tmp_path / "data", tmp_path / "s.log", SHAPEBAG_MAX_UPLOAD_BYTES=str(LIMIT), SHAPEBAG_WORKERS="0"
    )
    try:
        total = 200 * LIMIT  # 200 MB offered, no Content-Length to trust
        sent, answer = _send_until_answered(int(base.rsplit(":", 1)[1]), total)
        assert answer.startswith(b"HTTP/1.1 413"), answer[:200]
        assert b"larger than the limit" in answer
        # the server stopped reading at the limit: what we managed to send is the limit plus socket buffers
        assert sent < 20 * LIMIT, f"sent {sent} bytes before the 413"
        assert httpx.get(f"{base}/healthz").status_code == 200
        # a declared Content-Length over the limit is refused before reading any of the body
        r = httpx.post(f"{base}/models", content=b"x" * (3 * LIMIT), headers=MULTIPART_HEADERS)
        assert r.status_code == 413
    finally:
        server.stop()
    print(f"413 after {sent / 1e6:.1f} MB of a {total / 1e6:.0f} MB upload (limit {LIMIT / 1e6:g} MB)")


def test_a_full_queue_answers_503_with_retry_after(settings, corpus):
    settings = make_settings(settings.data_dir, workers=0, queue_limit=2)
    with TestClient(create_app(settings)) as client:
        codes = []
        for path, _ in corpus.files[:4]:
            r = client.post("/models", files={"file": (path.name, path.read_bytes())})
            codes.append(r.status_code)
        assert codes == [202, 202, 503, 503]
        assert int(r.headers["retry-after"]) > 0 and r.json()["error"]["code"] == "queue_full"
        assert client.get("/models").json()["count"] == 2


def _pool_processes(pid: int) -> set[int]:
    """Query-pool processes (spawned interpreters) under the server; with workers=0 there are no others."""
    out = set()
    for child in descendants(pid):
        try:
            cmd = Path(f"/proc/{child}/cmdline").read_bytes()
        except OSError:
            continue
        if b"spawn_main" in cmd:
            out.add(child)
    return out


@pytest.mark.slow
def test_describe_time_limit_answers_in_time_and_leaves_no_process(data_dir, corpus, tmp_path):
    limit = 2.0
    server, base = start_server(
        data_dir,
        tmp_path / "s.log",
        SHAPEBAG_WORKERS="0",
        SHAPEBAG_DESCRIBE_TIMEOUT_S=str(limit),
        SHAPEBAG_DESCRIBE__K="300",
        SHAPEBAG_DESCRIBE__TARGET_VERTICES="16000",  # 16k vertices: a sparse solve of many seconds
    )
    seen: set[int] = set()
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            seen.update(_pool_processes(server.pid))
            time.sleep(0.05)

    watcher = threading.Thread(target=watch, daemon=True)
    try:
        with httpx.Client(base_url=base, timeout=120) as http:
            assert http.get("/readyz").json()["checks"]["indexed_models"] > 0  # (no workers: not "ready")
            path, _ = corpus.held_out[0]
            watcher.start()
            t = time.perf_counter()
            r = http.post(
                "/search", content=multipart(path.name, path.read_bytes()), headers=MULTIPART_HEADERS
            )
            elapsed = time.perf_counter() - t
            done.set()
            watcher.join()
            assert r.status_code == 504 and r.json()["error"]["code"] == "describe_timeout", r.text
            assert elapsed < limit + 3.0, f"answered after {elapsed:.1f} s with a {limit} s limit"
            assert seen, "no pool process was seen describing"
            wait_for(lambda: not (_pool_processes(server.pid) & seen), timeout_s=10)
            assert http.get("/healthz").status_code == 200
    finally:
        done.set()
        server.stop()
    print(f"504 after {elapsed:.2f} s (limit {limit} s); pool processes {sorted(seen)} gone")
