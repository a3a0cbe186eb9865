"""`shapebag serve --processes 2` on each engine: two uvicorn worker processes on one port, each with its
own live index following the database, answer the same query identically, and a delete served by one
reaches the other (issue 13: "`uvicorn --workers N` works on one host the same way" as replicas).
SQLite: one data directory (WAL) shared by the processes of one host; PostgreSQL: blobs in the database."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import pytest

from tests.pg_server import db_url, pg_admin_url  # noqa: F401 (fixtures)
from tests.reliability.helpers import FAST_ENV

pytestmark = [pytest.mark.slow]  # the PostgreSQL case is marked postgres by db_url
TOKEN = "processes-test-token-kkkkkkkkkkk"
SEARCH_COUNT = re.compile(
    r'^shapebag_request_seconds_count\{[^}]*method="POST",route="/search",status="200"\} (\S+)$', re.MULTILINE
)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _fresh(base: str, method: str, path: str, **kw) -> httpx.Response:
    """A request on a new connection: the kernel hands each one to either process."""
    with httpx.Client(base_url=base, timeout=60) as c:
        return c.request(method, path, **kw)


def _wait(predicate, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")


def _search(base: str, mesh: Path) -> list[tuple[int, float]]:
    r = _fresh(base, "POST", "/search", files={"file": (mesh.name, mesh.read_bytes())}, data={"k": "5"})
    assert r.status_code == 200, r.text
    return [(hit["model_id"], round(hit["distance"], 6)) for hit in r.json()["data"]]


def test_two_api_processes_answer_identically(db_url, tmp_path, corpus):  # noqa: F811
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    env = {
        **os.environ,
        **FAST_ENV,
        "SHAPEBAG_DATABASE_URL": db_url,
        "SHAPEBAG_BLOB_BACKEND": "database" if db_url else "filesystem",
        "SHAPEBAG_ADMIN_TOKEN": TOKEN,
        "SHAPEBAG_AUTO_VOCABULARY_MIN_MODELS": str(len(corpus.seeded)),  # fitted once, by either process
        "SHAPEBAG_SEARCH_PROCESSES": "1",
    }
    cmd = [
        sys.executable,
        "-m",
        "app.cli",
        "serve",
        "--data-dir",
        str(tmp_path / "d"),
        "--port",
        str(port),
        "--processes",
        "2",
        "--workers",
        "1",
    ]
    log = open(tmp_path / "serve.log", "wb")  # noqa: SIM115 - closed in finally
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        _wait(lambda: _healthy(base), 90, "/healthz")
        for path, label in corpus.seeded:
            r = _fresh(
                base,
                "POST",
                "/models",
                files={"file": (path.name, path.read_bytes())},
                data={"label": label, "name": path.stem},
            )
            assert r.status_code == 202, r.text
        n = len(corpus.seeded)

        def caught_up() -> bool:  # ten fresh connections in a row see every model indexed
            return all(_indexed(base) == n for _ in range(10))

        _wait(caught_up, 300, f"{n} models indexed by both processes")
        query = corpus.held_out[0][0]
        with ThreadPoolExecutor(4) as pool:  # concurrent requests: both processes take some
            answers = list(pool.map(lambda _: _search(base, query), range(16)))
        assert all(a == answers[0] for a in answers), answers
        assert len(answers[0]) == 5

        # each process counts the searches it served: a count strictly between 0 and 16 proves that the
        # other process served the rest (a single process would show 16, an idle one 0)
        counts: list[float] = []
        for _ in range(60):
            m = SEARCH_COUNT.search(_fresh(base, "GET", "/metrics").text)
            counts.append(float(m.group(1)) if m else 0.0)
            if 0 < counts[-1] < 16:
                break
        assert 0 < counts[-1] < 16, f"per-process search counts seen: {counts}"

        gone = answers[0][0][0]  # deleted through one process ...
        r = _fresh(base, "DELETE", f"/models/{gone}", headers={"X-Admin-Token": TOKEN})
        assert r.status_code == 204, r.text

        def dropped() -> bool:  # ... and gone from both indexes
            return all(gone not in [i for i, _ in _search(base, query)] for _ in range(8))

        _wait(dropped, 60, f"model {gone} dropped by both processes")
        with ThreadPoolExecutor(4) as pool:
            after = list(pool.map(lambda _: _search(base, query), range(8)))
        assert all(a == after[0] for a in after)  # both processes again answer identically
        # each model's index distance is what it was; the order may change, since the fusion re-rank
        # expands the query with its nearest models, and the deleted one was the nearest
        before = dict(answers[0])
        assert gone not in dict(after[0]) and all(before[i] == d for i, d in after[0] if i in before)
    finally:
        proc.terminate()  # uvicorn's parent stops its processes, which stop their workers
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        log.close()
        print((tmp_path / "serve.log").read_text(errors="replace")[-4000:])


def _healthy(base: str) -> bool:
    try:
        return _fresh(base, "GET", "/healthz").status_code == 200
    except httpx.HTTPError:
        return False


def _indexed(base: str) -> int:
    return int(_fresh(base, "GET", "/readyz").json()["checks"]["indexed_models"])
