"""Worker processes for real: a killed worker's job is retried after its lease; dead workers are replaced;
a query that outruns the time limit answers 504 and the pool recovers."""

from __future__ import annotations

import os
import signal
import time

import pytest
from fastapi.testclient import TestClient

from app.config import DescribeSettings
from app.main import create_app
from app.services import ingestion
from app.services.context import open_context
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.worker.processes import WorkerPool
from app.worker.runner import Worker
from tests.conftest import make_settings, wait_for

pytestmark = pytest.mark.slow


def test_a_killed_workers_job_is_retried_when_its_lease_expires(tmp_path, corpus):
    # the default (slower) spectrum so the job is still running when we kill its worker
    settings = make_settings(tmp_path / "d", lease_seconds=1.5, describe=DescribeSettings(k=300, m=100))
    ctx = open_context(settings)
    path, _ = corpus.seeded[0]
    sub = ingestion.submit(ctx, path.read_bytes(), path.name)

    def job():
        with ctx.db.read() as conn:
            return jobs_repo.get(conn, sub.job_id)

    pool = WorkerPool(ctx.settings, 1, prefix="doomed")
    pool.start()
    try:
        wait_for(lambda: job().state == "running", timeout_s=60, interval_s=0.02)
        os.kill(pool.processes[0].pid, signal.SIGKILL)  # crash mid-job
        pool.processes[0].join(10)
    finally:
        pool.stop()
    assert job().state == "running" and job().attempts == 1
    assert jobs_repo.claim(ctx.db, "too-early", 1.5, 3) is None  # the dead worker's lease still holds
    wait_for(lambda: job().lease_until < time.time(), timeout_s=10)
    Worker(ctx, "survivor").run_once()
    assert job().state == "done" and job().attempts == 2 and job().worker == "survivor"


def test_dead_embedded_worker_is_replaced_and_slow_queries_time_out(data_dir, corpus):
    with TestClient(create_app(make_settings(data_dir, workers=1))) as client:
        runtime = client.app.state.runtime
        wait_for(lambda: client.get("/readyz").status_code == 200, timeout_s=30)
        first = runtime.workers.processes[0]
        os.kill(first.pid, signal.SIGKILL)
        first.join(10)
        wait_for(
            lambda: runtime.workers.processes[0] is not first and runtime.workers.alive() == 1, timeout_s=30
        )
        wait_for(lambda: client.get("/readyz").status_code == 200, timeout_s=30)

        path, _ = corpus.seeded[0]
        runtime.describer.timeout_s = 0.001
        r = client.post("/search", files={"file": (path.name, path.read_bytes())})
        assert r.status_code == 504 and r.json()["error"]["code"] == "describe_timeout"
        runtime.describer.timeout_s = 60
        r = client.post("/search", files={"file": (path.name, path.read_bytes())})
        assert r.status_code == 200 and r.json()["count"] > 0


def test_worker_names_differ_across_containers_whose_parents_share_a_pid(monkeypatch):
    from app.worker import processes

    monkeypatch.setattr(processes.os, "getpid", lambda: 1)  # a container's entry process
    names = set()
    for host in ("3f2a9c1d0b7e", "8e1b44c0a9f2"):  # compose gives each container its own hostname
        monkeypatch.setattr(processes.socket, "gethostname", lambda host=host: host)
        names |= {processes.process_name("worker", slot) for slot in range(2)}
    assert len(names) == 4
    assert processes.process_name("worker", 0) == "worker@8e1b44c0a9f2-1-0"


def test_a_job_past_the_worker_memory_cap_fails_once_with_the_reason(settings, corpus, monkeypatch):
    """MemoryError (RLIMIT_AS in a worker process) is not transient: no retries, a clear reason."""
    ctx = open_context(settings)
    path, _ = corpus.seeded[0]
    sub = ingestion.submit(ctx, path.read_bytes(), path.name)

    def too_big(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(ingestion, "describe_and_view", too_big)
    Worker(ctx, "capped").run_forever(exit_when_idle=True)
    with ctx.db.read() as conn:
        job = jobs_repo.get(conn, sub.job_id)
        model = models_repo.get(conn, sub.model.id)
    assert job.state == "failed" and job.attempts == 1
    assert model.status == "failed" and f"worker limit of {settings.worker_memory_mb} MB" in model.error
