"""Workers as real processes on one queue (SQLite and PostgreSQL): 8 claimers, 500 jobs, each done
exactly once; a worker killed with SIGKILL half-way through a job: its job is finished once, by another."""

from __future__ import annotations

import multiprocessing
import os
import queue
import signal

import pytest

from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from tests.storage import claimers

pytestmark = pytest.mark.slow
WORKERS, JOBS = 8, 500
CTX = multiprocessing.get_context("spawn")  # no inherited connections or locks


def test_claim_race_each_job_done_exactly_once(db, db_url, tmp_path):
    with db.write() as conn:
        ids = [jobs_repo.enqueue(conn, "ingest") for _ in range(JOBS)]
    barrier, results = CTX.Barrier(WORKERS), CTX.Queue()
    args = [(db_url, str(tmp_path), f"w{i}", barrier, results) for i in range(WORKERS)]
    procs = [CTX.Process(target=claimers.claim_until_empty, args=a) for a in args]
    for p in procs:
        p.start()
    finished: dict[str, list[int]] = {}
    try:
        for _ in procs:  # read before join: a full pipe would block a child's exit
            name, done = results.get(timeout=600)
            finished[name] = done
    except queue.Empty:
        pytest.fail(f"only {len(finished)} of {WORKERS} workers reported")
    finally:
        for p in procs:
            p.join(timeout=60)
    assert all(p.exitcode == 0 for p in procs)
    every = [i for done in finished.values() for i in done]
    assert sorted(every) == sorted(ids)  # none lost, none twice
    with db.read() as conn:
        rows = conn.execute("SELECT state, attempts, COUNT(*) FROM jobs GROUP BY state, attempts").fetchall()
    assert [tuple(r) for r in rows] == [("done", 1, JOBS)]  # a second claim would have attempts == 2


def test_worker_killed_mid_job_its_job_finishes_once(db, db_url, tmp_path):
    with db.write() as conn:
        mid = models_repo.insert(
            conn, name="m", label=None, metadata={}, sha256="k", file_type="obj", size_bytes=1
        )
        jid = jobs_repo.enqueue(conn, "ingest", model_id=mid)
    claimed = CTX.Event()
    proc = CTX.Process(target=claimers.claim_then_hang, args=(db_url, str(tmp_path), claimed))
    proc.start()
    try:
        assert claimed.wait(timeout=300), "the worker never claimed"
    finally:
        os.kill(proc.pid, signal.SIGKILL)  # mid-job, inside its write transaction
        proc.join(timeout=60)
    assert proc.exitcode == -signal.SIGKILL

    with db.read() as conn:  # its half-done write was rolled back
        assert models_repo.get(conn, mid).n_vertices is None
    rescued = jobs_repo.claim(db, "rescuer", lease_seconds=60, max_attempts=3)
    assert rescued is not None and rescued.id == jid and rescued.attempts == 2
    with db.write() as conn:  # the dead worker's lock went with it (a hang here: lock_timeout raises)
        jobs_repo.mark_done(conn, jid, {})
        models_repo.set_ready(conn, mid, 300)
    assert jobs_repo.claim(db, "rescuer", lease_seconds=60, max_attempts=3) is None
    with db.read() as conn:
        job, model = jobs_repo.get(conn, jid), models_repo.get(conn, mid)
    assert job.state == "done" and job.worker == "rescuer" and job.attempts == 2
    assert model.status == "ready" and model.n_vertices == 300
