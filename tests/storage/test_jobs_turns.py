"""The ingest queue serves clients in turn (issue 34): the next job is the oldest of the client running
fewest, so one client's flood delays only itself. On SQLite and PostgreSQL (tests/storage/conftest.py)."""

from __future__ import annotations

from app.storage import jobs as jobs_repo


def _enqueue(db, client: str, n: int = 1) -> list[int]:
    with db.write() as conn:
        return [jobs_repo.enqueue(conn, "ingest", client=client) for _ in range(n)]


def _claim(db, worker: str = "w"):
    job = jobs_repo.claim(db, worker, lease_seconds=60, max_attempts=3)
    assert job is not None
    return job


def test_a_flood_queued_first_delays_another_client_by_one_job_at_most(db):
    flood = _enqueue(db, "addr:10.0.0.1", 6)
    normal = _enqueue(db, "addr:10.0.0.2")
    first = _claim(db, "w1")
    assert first.id == flood[0] and first.client == "addr:10.0.0.1"  # both run none: the oldest job
    assert _claim(db, "w2").id == normal[0]  # the flooder runs one: the other client goes next
    assert _claim(db, "w3").id == flood[1]  # nobody else waits: the flood goes on
    with db.read() as conn:
        assert jobs_repo.get(conn, normal[0]).client == "addr:10.0.0.2"  # type: ignore[union-attr]


def test_clients_alternate_while_both_have_jobs_running(db):
    a = _enqueue(db, "token:api", 3)
    b = _enqueue(db, "addr:10.0.0.9", 3)
    order = [_claim(db, f"w{i}").id for i in range(6)]
    assert order == [a[0], b[0], a[1], b[1], a[2], b[2]]


def test_a_finished_job_frees_its_client_turn(db):
    a = _enqueue(db, "a", 2)
    b = _enqueue(db, "b", 2)
    assert _claim(db).id == a[0]
    with db.write() as conn:
        jobs_repo.mark_done(conn, a[0], {})
    assert _claim(db).id == a[1]  # a runs none again: its older job goes before b's
    assert _claim(db).id == b[0]


def test_a_dead_workers_job_is_taken_before_any_queued_one(db):
    [late] = _enqueue(db, "a")
    job = jobs_repo.claim(db, "dead", lease_seconds=-1, max_attempts=3)  # a lease already expired
    assert job is not None and job.id == late
    [fresh] = _enqueue(db, "b")
    again = _claim(db, "alive")
    assert again.id == late and again.attempts == 2
    assert _claim(db, "other").id == fresh


def test_jobs_without_a_client_are_one_client_among_others(db):
    with db.write() as conn:
        fit = jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={})
    uploads = _enqueue(db, "a", 2)
    assert _claim(db).id == fit
    assert _claim(db).id == uploads[0]
