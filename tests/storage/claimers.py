"""Worker bodies for the claim race and the killed-worker tests (run in spawned processes)."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

from app.storage import jobs as jobs_repo
from app.storage.engine import open_database


def claim_until_empty(url: str, data_dir: str, name: str, barrier: Any, results: Any) -> None:
    """Claim and finish jobs until none is left; report the ids this worker finished."""
    db = open_database(Path(data_dir), url)
    barrier.wait(timeout=300)  # every worker starts claiming at once
    finished: list[int] = []
    while (job := jobs_repo.claim(db, name, lease_seconds=600, max_attempts=3)) is not None:
        with db.write() as conn:
            jobs_repo.mark_done(conn, job.id, {"worker": 1.0})
        finished.append(job.id)
    results.put((name, finished))


def claim_then_hang(url: str, data_dir: str, claimed: Any) -> None:
    """Claim one job, start its write transaction, then wait to be killed (SIGKILL) half-way."""
    db = open_database(Path(data_dir), url)
    # lease already expired: its expiry is test_jobs' subject (moved clock); here the rescuer may take
    # the job as soon as this worker is dead, with no waiting on a clock
    job = jobs_repo.claim(db, "doomed", lease_seconds=-1, max_attempts=3)
    assert job is not None
    with db.write() as conn:
        conn.execute("UPDATE models SET n_vertices = 1 WHERE id = ?", (job.model_id,))
        claimed.set()
        threading.Event().wait()  # until killed, holding the write lock
