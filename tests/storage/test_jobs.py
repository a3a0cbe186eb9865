"""The job queue, on SQLite and PostgreSQL (tests/storage/conftest.py): claims are exclusive, leases
expire into retries, attempts run out into failure."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest

from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage.db import Database
from app.storage.postgres import Row


def _model(db) -> int:
    with db.write() as conn:
        return models_repo.insert(
            conn, name="m", label=None, metadata={}, sha256=str(time.time_ns()), file_type="obj", size_bytes=1
        )


def test_schema_version_and_wal_mode(db):
    with db.read() as conn:
        versions = conn.execute("SELECT version FROM schema_migrations ORDER BY version").fetchall()
        assert [r[0] for r in versions] == [1, 2, 3, 4, 5, 6]
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


# Job-queue functions called directly: the latest job
# of a model, a failure's record, a release for retry, and the live-worker count at its time boundary.
# On SQLite and PostgreSQL through tests/storage/conftest.py's `db`; the claim also on SQLite with
# rows that answer only to their exact column names, as PostgreSQL's do.


def _numbered_model(db, n: int) -> int:
    with db.write() as conn:
        return models_repo.insert(
            conn, name=f"m{n}", label=None, metadata={}, sha256=f"{n:064x}", file_type="obj", size_bytes=1
        )


def test_latest_for_model_is_its_newest_job_only(db):
    a, b, c = _numbered_model(db, 1), _numbered_model(db, 2), _numbered_model(db, 3)
    with db.write() as conn:
        first = jobs_repo.enqueue(conn, "ingest", model_id=a)
        other = jobs_repo.enqueue(conn, "ingest", model_id=b)
        second = jobs_repo.enqueue(conn, "ingest", model_id=a, payload={"again": True})
    with db.read() as conn:
        latest = jobs_repo.latest_for_model(conn, a)
        assert latest is not None and latest.id == second and latest.payload == {"again": True}
        assert jobs_repo.latest_for_model(conn, b).id == other  # type: ignore[union-attr]
        assert jobs_repo.latest_for_model(conn, c) is None
    assert first < other < second


def test_mark_failed_records_the_error_and_keeps_or_replaces_timings(db):
    with db.write() as conn:
        kept, replaced = jobs_repo.enqueue(conn, "ingest"), jobs_repo.enqueue(conn, "ingest")
    for _ in range(2):
        assert jobs_repo.claim(db, "w", lease_seconds=60, max_attempts=3) is not None
    with db.write() as conn:
        jobs_repo.mark_done(conn, kept, {"load": 1.5})  # timings written first
        jobs_repo.mark_failed(conn, kept, "boom")
        jobs_repo.mark_failed(conn, replaced, "bad mesh", {"load": 0.25})
    with db.read() as conn:
        k, r = jobs_repo.get(conn, kept), jobs_repo.get(conn, replaced)
    assert (k.state, k.error, k.timings, k.lease_until) == ("failed", "boom", {"load": 1.5}, None)
    assert (r.state, r.error, r.timings, r.lease_until) == ("failed", "bad mesh", {"load": 0.25}, None)


def test_release_for_retry_requeues_with_the_error_and_no_owner(db):
    with db.write() as conn:
        job_id = jobs_repo.enqueue(conn, "ingest")
    assert jobs_repo.claim(db, "w1", lease_seconds=60, max_attempts=3).worker == "w1"  # type: ignore[union-attr]
    with db.write() as conn:
        jobs_repo.release_for_retry(conn, job_id, "transient: disk full")
        again = jobs_repo.get(conn, job_id)
        assert jobs_repo.queue_depth(conn) == {"queued": 1, "running": 0}
    assert again is not None
    assert (again.state, again.error, again.worker, again.lease_until) == (
        "queued",
        "transient: disk full",
        None,
        None,
    )
    retried = jobs_repo.claim(db, "w2", lease_seconds=60, max_attempts=3)
    assert retried is not None and retried.id == job_id and retried.attempts == 2 and retried.worker == "w2"


def test_live_workers_counts_heartbeats_within_the_window_inclusive(db, monkeypatch):
    clock = {"now": 1_000_000.0}
    monkeypatch.setattr(jobs_repo, "time", SimpleNamespace(time=lambda: clock["now"]))
    jobs_repo.heartbeat(db, "old", 1)
    clock["now"] += 5.0
    jobs_repo.heartbeat(db, "new", 2)
    clock["now"] += 10.0  # old: 15 s ago, new: 10 s ago
    with db.read() as conn:
        assert jobs_repo.live_workers(conn, within_s=9.5) == 0
        assert jobs_repo.live_workers(conn, within_s=10.0) == 1  # exactly at the edge still counts
        assert jobs_repo.live_workers(conn, within_s=15.0) == 2
    jobs_repo.forget_worker(db, "new")
    with db.read() as conn:
        assert jobs_repo.live_workers(conn, within_s=60.0) == 1


def test_an_unknown_job_kind_is_refused_in_words(db):
    with db.write() as conn, pytest.raises(ValueError, match="^unknown job kind 'reindex'$"):
        jobs_repo.enqueue(conn, "reindex")


class _ExactNameRows(Database):
    """SQLite whose rows answer only to their exact column names, as PostgreSQL's (postgres.Row) do:
    sqlite3.Row would also answer row["ID"]."""

    def _open(self):
        conn = super()._open()
        conn.row_factory = lambda cursor, values: Row(values, [c[0] for c in cursor.description])
        return conn


def test_claim_reads_its_rows_by_their_exact_column_names(tmp_path, monkeypatch):
    clock = {"now": 1_000_000.0}
    monkeypatch.setattr(jobs_repo, "time", SimpleNamespace(time=lambda: clock["now"]))
    db = _ExactNameRows(tmp_path / "shapebag.db")
    db.migrate()
    model = _numbered_model(db, 1)
    with db.write() as conn:
        spent = jobs_repo.enqueue(conn, "ingest", model_id=model)
    first = jobs_repo.claim(db, "w1", lease_seconds=10, max_attempts=1)
    assert first is not None and first.id == spent and first.worker == "w1"
    with db.write() as conn:
        fresh = jobs_repo.enqueue(conn, "ingest", model_id=model)
    clock["now"] += 60.0  # w1's lease expired with its one attempt spent
    second = jobs_repo.claim(db, "w2", lease_seconds=10, max_attempts=1)
    assert second is not None and second.id == fresh and second.worker == "w2" and second.attempts == 1
    with db.read() as conn:
        given_up = jobs_repo.get(conn, spent)
        failed = models_repo.get(conn, model)
    assert given_up is not None and given_up.state == "failed"
    assert given_up.error == "gave up after 1 attempts: its worker stopped (lease expired)"
    assert failed is not None and failed.status == "failed" and failed.error == given_up.error
