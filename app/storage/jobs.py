"""Repository of jobs: a small queue in SQLite with leases.

A worker claims a runnable job in one transaction (SQLite: BEGIN IMMEDIATE; PostgreSQL: row locks,
`FOR UPDATE SKIP LOCKED`, so claims on many hosts do not wait on each other) and holds it for
`lease_seconds`; if the worker dies, the lease expires and another worker takes the job again,
until `max_attempts` claims have been spent.

Clients are served in turn: each job records the client it is for, and the next queued job is the
oldest of the client with the fewest jobs running (then the oldest job). A client that queues 600
uploads delays only itself: another client's upload waits for at most one job per worker.
"""

from __future__ import annotations

import json
import sqlite3
import time
from dataclasses import dataclass, field

from app.storage.db import Database, utcnow

KINDS = ("ingest", "rebuild_vocabulary", "rebuild_index")


@dataclass(frozen=True)
class JobRecord:
    id: int
    kind: str
    state: str
    model_id: int | None
    attempts: int
    lease_until: float | None
    worker: str | None
    error: str | None
    created_at: str
    updated_at: str
    payload: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    client: str = ""  # who it is for (services/clients.py); '' for maintenance jobs


def _record(row: sqlite3.Row | None) -> JobRecord | None:
    if row is None:
        return None
    d = dict(row)
    d["payload"] = json.loads(d["payload"] or "{}")
    d["timings"] = json.loads(d["timings"] or "{}")
    return JobRecord(**d)


def enqueue(
    conn: sqlite3.Connection,
    kind: str,
    model_id: int | None = None,
    payload: dict | None = None,
    client: str = "",
) -> int:
    if kind not in KINDS:
        raise ValueError(f"unknown job kind {kind!r}")
    now = utcnow()
    cur = conn.execute(
        "INSERT INTO jobs (kind, state, model_id, payload, created_at, updated_at, client)"
        " VALUES (?, 'queued', ?, ?, ?, ?, ?)",
        (kind, model_id, json.dumps(payload or {}), now, now, client),
    )
    return int(cur.lastrowid or 0)


def get(conn: sqlite3.Connection, job_id: int) -> JobRecord | None:
    return _record(conn.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone())


def latest_for_model(conn: sqlite3.Connection, model_id: int) -> JobRecord | None:
    row = conn.execute(
        "SELECT * FROM jobs WHERE model_id = ? ORDER BY id DESC LIMIT 1", (model_id,)
    ).fetchone()
    return _record(row)


def claim(db: Database, worker: str, lease_seconds: float, max_attempts: int) -> JobRecord | None:
    """Take the oldest queued job, or one whose lease expired; give up on jobs out of attempts."""
    now = time.time()
    with db.queue() as conn:
        spent = conn.execute(
            "SELECT id, model_id, attempts FROM jobs"
            " WHERE state = 'running' AND lease_until < ? AND attempts >= ?" + db.skip_locked,
            (now, max_attempts),
        ).fetchall()
        for row in spent:
            reason = f"gave up after {row['attempts']} attempts: its worker stopped (lease expired)"
            _finish(conn, row["id"], "failed", reason, None)
            if row["model_id"] is not None:
                conn.execute(
                    "UPDATE models SET status = 'failed', error = ?, updated_at = ?"
                    " WHERE id = ? AND status = 'queued'",
                    (reason, utcnow(), row["model_id"]),
                )
        row = conn.execute(  # a dead worker's job first: it has waited longest
            "SELECT * FROM jobs WHERE state = 'running' AND lease_until < ? ORDER BY id LIMIT 1"
            + db.skip_locked,
            (now,),
        ).fetchone()
        row = row or _next_in_turn(conn, db.skip_locked)
        if row is None:
            return None
        conn.execute(
            "UPDATE jobs SET state = 'running', attempts = attempts + 1, lease_until = ?, worker = ?,"
            " updated_at = ?"
            " WHERE id = ?",
            (now + lease_seconds, worker, utcnow(), row["id"]),
        )
        return get(conn, row["id"])


# per client with queued jobs: its oldest, ordered by the client's running jobs, then age
_TURNS = (
    "SELECT q.first_id FROM"
    " (SELECT client, MIN(id) AS first_id FROM jobs WHERE state = 'queued' GROUP BY client) AS q"
    " LEFT JOIN (SELECT client, COUNT(*) AS n FROM jobs WHERE state = 'running' GROUP BY client) AS r"
    " ON r.client = q.client"
    " ORDER BY COALESCE(r.n, 0), q.first_id LIMIT ?"
)
TURN_CANDIDATES = 8


def _next_in_turn(conn: sqlite3.Connection, skip_locked: str) -> sqlite3.Row | None:
    """The next queued job, clients in turn. The aggregate takes no row locks (PostgreSQL refuses FOR
    UPDATE with GROUP BY), so each candidate is locked on its own; one another worker holds is skipped."""
    for (job_id,) in conn.execute(_TURNS, (TURN_CANDIDATES,)).fetchall():
        row = conn.execute(
            "SELECT * FROM jobs WHERE id = ? AND state = 'queued'" + skip_locked, (job_id,)
        ).fetchone()
        if row is not None:
            return row
    # every candidate taken meanwhile (many workers at once): the oldest job still free
    return conn.execute(
        "SELECT * FROM jobs WHERE state = 'queued' ORDER BY id LIMIT 1" + skip_locked
    ).fetchone()


def extend_lease(db: Database, job_id: int, worker: str, lease_seconds: float) -> bool:
    """Keep a long job's lease alive; False if the job is no longer ours."""
    with db.queue() as conn:
        cur = conn.execute(
            "UPDATE jobs SET lease_until = ? WHERE id = ? AND worker = ? AND state = 'running'",
            (time.time() + lease_seconds, job_id, worker),
        )
        return cur.rowcount == 1


def _finish(
    conn: sqlite3.Connection, job_id: int, state: str, error: str | None, timings: dict | None
) -> None:
    conn.execute(
        "UPDATE jobs SET state = ?, error = ?, timings = COALESCE(?, timings), lease_until = NULL,"
        " updated_at = ?"
        " WHERE id = ?",
        (state, error, json.dumps(timings) if timings is not None else None, utcnow(), job_id),
    )


def mark_done(conn: sqlite3.Connection, job_id: int, timings: dict) -> None:
    _finish(conn, job_id, "done", None, timings)


def mark_failed(conn: sqlite3.Connection, job_id: int, error: str, timings: dict | None = None) -> None:
    _finish(conn, job_id, "failed", error, timings)


def release_for_retry(conn: sqlite3.Connection, job_id: int, error: str) -> None:
    """Back to the queue after a transient failure; the error stays visible until the next outcome."""
    conn.execute(
        "UPDATE jobs SET state = 'queued', error = ?, lease_until = NULL, worker = NULL, updated_at = ?"
        " WHERE id = ?",
        (error, utcnow(), job_id),
    )


def queue_depth(conn: sqlite3.Connection) -> dict[str, int]:
    counts = {"queued": 0, "running": 0}
    for state, n in conn.execute(
        "SELECT state, COUNT(*) FROM jobs WHERE state IN ('queued', 'running') GROUP BY state"
    ):
        counts[state] = int(n)
    return counts


def pending(conn: sqlite3.Connection, kind: str) -> JobRecord | None:
    row = conn.execute(
        "SELECT * FROM jobs WHERE kind = ? AND state IN ('queued', 'running') ORDER BY id LIMIT 1", (kind,)
    ).fetchone()
    return _record(row)


def latest(conn: sqlite3.Connection, kind: str) -> JobRecord | None:
    """The newest job of `kind`, whatever its state (None when there was none)."""
    row = conn.execute("SELECT * FROM jobs WHERE kind = ? ORDER BY id DESC LIMIT 1", (kind,)).fetchone()
    return _record(row)


def heartbeat(db: Database, worker: str, pid: int) -> None:
    with db.queue() as conn:
        conn.execute(
            "INSERT INTO workers (name, pid, last_seen) VALUES (?, ?, ?)"
            " ON CONFLICT(name) DO UPDATE SET pid = excluded.pid, last_seen = excluded.last_seen",
            (worker, pid, time.time()),
        )


def live_workers(conn: sqlite3.Connection, within_s: float) -> int:
    cutoff = time.time() - within_s
    return int(conn.execute("SELECT COUNT(*) FROM workers WHERE last_seen >= ?", (cutoff,)).fetchone()[0])


def forget_worker(db: Database, worker: str) -> None:
    with db.write() as conn:
        conn.execute("DELETE FROM workers WHERE name = ?", (worker,))
