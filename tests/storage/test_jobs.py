"""The job queue, on SQLite and PostgreSQL (tests/storage/conftest.py): claims are exclusive, leases
expire into retries, attempts run out into failure."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

from app.storage import jobs as jobs_repo
from app.storage import models as models_repo


def _model(db) -> int:
    with db.write() as conn:
        return models_repo.insert(
            conn, name="m", label=None, metadata={}, sha256=str(time.time_ns()), file_type="obj", size_bytes=1
        )


def test_schema_version_and_wal_mode(db):
    with db.read() as conn:
        versions = conn.execute("SELECT version FROM schema_migrations ORDER BY version").fetchall()
        assert [r[0] for r in versions] == [1, 2, 3, 4, 5]
        if db.dialect == "sqlite":
            assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert db.ping()


def test_claims_are_exclusive_under_concurrency(db):
    with db.write() as conn:
        for _ in range(40):
            jobs_repo.enqueue(conn, "ingest")
    claimed: list[int] = []
    lock = threading.Lock()

    def claimer(name):
        while (job := jobs_repo.claim(db, name, lease_seconds=60, max_attempts=3)) is not None:
            with lock:
                claimed.append(job.id)

    threads = [threading.Thread(target=claimer, args=(f"w{i}",)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(claimed) == list(range(1, 41))  # each job exactly once


def test_expired_lease_is_retried_then_fails_with_reason(db, monkeypatch):
    # a clock the test moves (not 50 ms leases and sleeps, which a loaded machine outran)
    clock = {"now": 1_000_000.0}
    monkeypatch.setattr(jobs_repo, "time", SimpleNamespace(time=lambda: clock["now"]))
    mid = _model(db)
    with db.write() as conn:
        job_id = jobs_repo.enqueue(conn, "ingest", model_id=mid)
    first = jobs_repo.claim(db, "crashed", lease_seconds=10, max_attempts=2)
    assert first.id == job_id and first.attempts == 1 and first.state == "running"
    clock["now"] += 9.9
    assert jobs_repo.claim(db, "other", lease_seconds=10, max_attempts=2) is None  # lease still held
    clock["now"] += 0.2
    second = jobs_repo.claim(db, "other", lease_seconds=10, max_attempts=2)
    assert second.id == job_id and second.attempts == 2 and second.worker == "other"
    clock["now"] += 10.1
    assert jobs_repo.claim(db, "third", lease_seconds=10, max_attempts=2) is None
    with db.read() as conn:
        job = jobs_repo.get(conn, job_id)
        model = models_repo.get(conn, mid)
    assert job.state == "failed" and "2 attempts" in job.error
    assert model.status == "failed" and model.error == job.error


def test_extend_lease_only_for_the_owner(db, monkeypatch):
    clock = {"now": 1_000_000.0}
    monkeypatch.setattr(jobs_repo, "time", SimpleNamespace(time=lambda: clock["now"]))
    with db.write() as conn:
        jobs_repo.enqueue(conn, "rebuild_index")
    job = jobs_repo.claim(db, "a", lease_seconds=10, max_attempts=3)
    assert jobs_repo.extend_lease(db, job.id, "a", lease_seconds=60)
    assert not jobs_repo.extend_lease(db, job.id, "b", lease_seconds=60)
    clock["now"] += 30  # past the first lease, inside the extended one
    assert jobs_repo.claim(db, "b", lease_seconds=60, max_attempts=3) is None  # extended: not expired
    clock["now"] += 31
    assert jobs_repo.claim(db, "b", lease_seconds=60, max_attempts=3).worker == "b"  # now it has expired


def test_queue_depth_and_pending(db):
    with db.write() as conn:
        jobs_repo.enqueue(conn, "ingest")
        jobs_repo.enqueue(conn, "rebuild_vocabulary")
    jobs_repo.claim(db, "w", 60, 3)
    with db.read() as conn:
        assert jobs_repo.queue_depth(conn) == {"queued": 1, "running": 1}
        assert jobs_repo.pending(conn, "rebuild_vocabulary").state == "queued"
        assert jobs_repo.pending(conn, "rebuild_index") is None
