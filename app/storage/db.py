"""SQLite (WAL) access: one short-lived connection per unit of work, a tiny migrations table.

Several processes (the API, embedded and external workers) share the file; WAL lets readers run
beside the one writer, and writers take the lock up front (BEGIN IMMEDIATE) so a transaction never
fails half-way on a lock upgrade.
"""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

MIGRATIONS: list[str] = [
    # 1: initial schema
    """
    CREATE TABLE models (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        name TEXT NOT NULL,
        label TEXT,
        metadata TEXT NOT NULL DEFAULT '{}',
        sha256 TEXT NOT NULL UNIQUE,
        file_type TEXT NOT NULL,
        size_bytes INTEGER NOT NULL,
        status TEXT NOT NULL CHECK (status IN ('queued', 'ready', 'failed')),
        error TEXT,
        n_vertices INTEGER,
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL
    );
    CREATE INDEX models_label ON models(label);
    CREATE INDEX models_status ON models(status);
    CREATE TABLE jobs (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        kind TEXT NOT NULL CHECK (kind IN ('ingest', 'rebuild_vocabulary', 'rebuild_index')),
        state TEXT NOT NULL CHECK (state IN ('queued', 'running', 'done', 'failed')),
        model_id INTEGER,
        payload TEXT NOT NULL DEFAULT '{}',
        attempts INTEGER NOT NULL DEFAULT 0,
        lease_until REAL,
        worker TEXT,
        error TEXT,
        timings TEXT NOT NULL DEFAULT '{}',
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL
    );
    CREATE INDEX jobs_state ON jobs(state, id);
    CREATE TABLE vocabularies (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        path TEXT NOT NULL,
        created_at TEXT NOT NULL,
        trained_on INTEGER NOT NULL,
        size INTEGER NOT NULL,
        run TEXT NOT NULL,
        active INTEGER NOT NULL DEFAULT 0,
        metadata TEXT NOT NULL DEFAULT '{}'
    );
    CREATE UNIQUE INDEX one_active_vocabulary ON vocabularies(active) WHERE active = 1;
    CREATE TABLE bof (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        model_id INTEGER NOT NULL REFERENCES models(id) ON DELETE CASCADE,
        vocabulary_id INTEGER NOT NULL REFERENCES vocabularies(id) ON DELETE CASCADE,
        vector BLOB NOT NULL,
        UNIQUE (model_id, vocabulary_id)
    );
    CREATE INDEX bof_vocabulary_seq ON bof(vocabulary_id, seq);
    CREATE TABLE workers (
        name TEXT PRIMARY KEY,
        pid INTEGER NOT NULL,
        last_seen REAL NOT NULL
    );
    """,
    # 2: blobs in the database (SHAPEBAG_BLOB_BACKEND=database; storage/blobs_db.py): the shared copy
    # of meshes and descriptions when hosts share no filesystem
    """
    CREATE TABLE blobs (
        key TEXT PRIMARY KEY,
        data BLOB NOT NULL,
        size_bytes INTEGER NOT NULL,
        created_at TEXT NOT NULL
    );
    """,
    # 3: deleted model ids in order, so every API replica's live index drops them (LiveIndex.refresh)
    """
    CREATE TABLE deletions (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        model_id INTEGER NOT NULL
    );
    """,
    # 4: who each job is for (services/clients.py: 'token:api', 'addr:10.0.0.7'), so the queue can
    # serve clients in turn (jobs.claim)
    """
    ALTER TABLE jobs ADD COLUMN client TEXT NOT NULL DEFAULT '';
    CREATE INDEX jobs_state_client ON jobs(state, client, id);
    """,
    # 5: variants (storage/variants.py): geometric fingerprints (part 0 = the whole model, 1.. its
    # objects), the relations verified at ingest, and reviewers' decisions, which are never removed
    """
    CREATE TABLE fingerprints (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        model_id INTEGER NOT NULL REFERENCES models(id) ON DELETE CASCADE,
        part INTEGER NOT NULL,
        version INTEGER NOT NULL,
        vector BLOB NOT NULL,
        UNIQUE (model_id, part)
    );
    CREATE TABLE variant_links (
        model_id INTEGER NOT NULL REFERENCES models(id) ON DELETE CASCADE,
        other_id INTEGER NOT NULL REFERENCES models(id) ON DELETE CASCADE,
        relation TEXT NOT NULL,
        confidence REAL NOT NULL,
        evidence TEXT NOT NULL,
        created_at TEXT NOT NULL,
        PRIMARY KEY (model_id, other_id)
    );
    CREATE INDEX variant_links_other ON variant_links(other_id);
    CREATE TABLE variant_decisions (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        low_id INTEGER NOT NULL,
        high_id INTEGER NOT NULL,
        decision TEXT NOT NULL CHECK (decision IN ('keep_both', 'not_variant')),
        note TEXT,
        created_at TEXT NOT NULL
    );
    CREATE INDEX variant_decisions_pair ON variant_decisions(low_id, high_id, seq);
    """,
    # 6: object rows (storage/objects.py): the distinct objects of a multi-object file, each described
    # and indexed as a row of the file too, with its BoF per vocabulary version
    """
    CREATE TABLE model_objects (
        model_id INTEGER NOT NULL REFERENCES models(id) ON DELETE CASCADE,
        part INTEGER NOT NULL,
        copies INTEGER NOT NULL,
        share REAL NOT NULL,
        PRIMARY KEY (model_id, part)
    );
    CREATE TABLE object_bof (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        model_id INTEGER NOT NULL REFERENCES models(id) ON DELETE CASCADE,
        part INTEGER NOT NULL,
        vocabulary_id INTEGER NOT NULL REFERENCES vocabularies(id) ON DELETE CASCADE,
        vector BLOB NOT NULL,
        UNIQUE (model_id, part, vocabulary_id)
    );
    CREATE INDEX object_bof_vocabulary_seq ON object_bof(vocabulary_id, seq);
    """,
]


def utcnow() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


class Database:
    """The data directory's shapebag.db (storage/postgres.py: the same interface on PostgreSQL)."""

    dialect = "sqlite"
    skip_locked = ""  # the claim's row-lock clause: none here, the write lock already serialises

    def __init__(self, path: str | Path, busy_timeout_s: float = 30.0) -> None:
        self.path = Path(path)
        self.busy_timeout_s = busy_timeout_s

    def _open(self) -> sqlite3.Connection:
        conn = sqlite3.connect(self.path, timeout=self.busy_timeout_s, isolation_level=None)
        conn.row_factory = sqlite3.Row
        conn.execute("PRAGMA foreign_keys = ON")
        conn.execute("PRAGMA synchronous = NORMAL")
        return conn

    @contextmanager
    def read(self) -> Iterator[sqlite3.Connection]:
        """A connection in autocommit mode, for reads (each statement sees a consistent snapshot)."""
        conn = self._open()
        try:
            yield conn
        finally:
            conn.close()

    @contextmanager
    def write(self) -> Iterator[sqlite3.Connection]:
        """One write transaction, BEGIN IMMEDIATE ... COMMIT (ROLLBACK on any exception)."""
        conn = self._open()
        try:
            _begin_immediate(conn, self.busy_timeout_s)
            try:
                yield conn
            except BaseException:
                conn.execute("ROLLBACK")
                raise
            conn.execute("COMMIT")
        finally:
            conn.close()

    @contextmanager
    def queue(self) -> Iterator[sqlite3.Connection]:
        """The job queue's transaction: the write lock here; row locks only on PostgreSQL."""
        with self.write() as conn:
            yield conn

    def migrate(self) -> int:
        """Create/upgrade the schema; returns the schema version. Safe to call from every process."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        conn = self._open()
        try:
            conn.execute("PRAGMA journal_mode = WAL")
            _begin_immediate(conn, self.busy_timeout_s)
            try:
                conn.execute(
                    "CREATE TABLE IF NOT EXISTS schema_migrations"
                    " (version INTEGER PRIMARY KEY, applied_at TEXT)"
                )
                done = {r[0] for r in conn.execute("SELECT version FROM schema_migrations")}
                for version, script in enumerate(MIGRATIONS, start=1):
                    if version in done:
                        continue
                    for statement in _statements(script):
                        conn.execute(statement)
                    conn.execute("INSERT INTO schema_migrations VALUES (?, ?)", (version, utcnow()))
            except BaseException:
                conn.execute("ROLLBACK")
                raise
            conn.execute("COMMIT")
            return len(MIGRATIONS)
        finally:
            conn.close()

    def ping(self) -> bool:
        try:
            with self.read() as conn:
                conn.execute("SELECT 1 FROM schema_migrations LIMIT 1").fetchall()
            return True
        except sqlite3.Error:
            return False


def _statements(script: str) -> list[str]:
    # executescript() would COMMIT our transaction; the schema has no ';' inside statements
    return [s.strip() for s in script.split(";") if s.strip()]


def _begin_immediate(conn: sqlite3.Connection, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            conn.execute("BEGIN IMMEDIATE")
            return
        except sqlite3.OperationalError as exc:  # busy beyond the driver's own timeout
            if "locked" not in str(exc) or time.monotonic() > deadline:
                raise
            time.sleep(0.05)
