"""End to end: `shapebag serve` in a subprocess on a free loopback port, driven with httpx."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys

import httpx
import pytest

from tests.conftest import wait_for

pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_served_over_http(data_dir, corpus, tmp_path):
    port = _free_port()
    env = dict(
        os.environ,
        SHAPEBAG_DATA_DIR=str(data_dir),
        SHAPEBAG_ADMIN_TOKEN="e2e-secret-kkkkkkkkkkkkkkkkkkkkk",
        SHAPEBAG_WORKERS="1",
        SHAPEBAG_DESCRIBE__K="40",
        SHAPEBAG_DESCRIBE__M="20",
        SHAPEBAG_DESCRIBE__TARGET_VERTICES="300",
        SHAPEBAG_POLL_INTERVAL_S="0.1",
    )
    log = open(tmp_path / "server.log", "w")  # noqa: SIM115 - outlives this block (the server writes to it)
    server = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--port", str(port)],
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        with httpx.Client(base_url=base, timeout=60) as http:

            def up():
                try:
                    return http.get("/readyz").status_code == 200
                except httpx.TransportError:
                    assert server.poll() is None, (tmp_path / "server.log").read_text()
                    return False

            wait_for(up, timeout_s=90, interval_s=0.3)
            assert http.get("/healthz").json() == {"status": "ok"}
            assert http.get("/openapi.json").json()["info"]["title"] == "shapebag"
            path, label = corpus.held_out[3]
            r = http.post("/models", files={"file": (path.name, path.read_bytes())}, data={"label": label})
            assert r.status_code == 202
            model_id = r.json()["model_id"]
            wait_for(lambda: http.get(f"/jobs/{r.json()['job_id']}").json()["state"] == "done", timeout_s=90)

            def top():
                res = http.post("/search", files={"file": (path.name, path.read_bytes())}, data={"k": "3"})
                return res.json() if res.json()["data"][0]["model_id"] == model_id else None

            result = wait_for(top, timeout_s=30)
            assert result["data"][0]["label"] == label and result["seconds"]["describe"] > 0
            png = http.get(f"/models/{model_id}/thumbnail.png")
            assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"
            assert "max-age" in png.headers["cache-control"]
            assert (data_dir / "thumbnails" / f"{model_id}-256.png").read_bytes() == png.content  # cached
            metrics = http.get("/metrics").text
            for name in (
                "shapebag_request_seconds_bucket",
                "shapebag_queue_depth",
                "shapebag_models{",
                "shapebag_describe_seconds_count",
            ):
                assert name in metrics
            assert 'shapebag_describe_seconds_count{where="ingest"} 1.0' in metrics
            assert 'shapebag_describe_seconds_count{where="query"}' in metrics
            assert http.post("/admin/index/rebuild").status_code == 401
            assert (
                http.post(
                    "/admin/index/rebuild", headers={"X-Admin-Token": "e2e-secret-kkkkkkkkkkkkkkkkkkkkk"}
                ).status_code
                == 202
            )
    finally:
        server.send_signal(signal.SIGTERM)
        try:
            code = server.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
            raise
        log.close()
    # uvicorn shuts down gracefully on SIGTERM, then re-raises the signal (exit status -15)
    text = (tmp_path / "server.log").read_text()
    assert code in (0, -signal.SIGTERM) and "Application shutdown complete" in text, text
