"""Repository of vocabulary versions and of each model's BoF vector per version."""

from __future__ import annotations

import json
import sqlite3
from dataclasses import dataclass, field

import numpy as np

from app.storage.db import utcnow


@dataclass(frozen=True)
class VocabularyRecord:
    id: int
    path: str
    created_at: str
    trained_on: int
    size: int
    run: str
    active: bool
    metadata: dict = field(default_factory=dict)


def _record(row: sqlite3.Row | None) -> VocabularyRecord | None:
    if row is None:
        return None
    d = dict(row)
    d["metadata"] = json.loads(d["metadata"] or "{}")
    d["active"] = bool(d["active"])
    return VocabularyRecord(**d)


def insert(
    conn: sqlite3.Connection,
    *,
    path: str,
    trained_on: int,
    size: int,
    run: str,
    metadata: dict,
    created_at: str | None = None,
) -> int:
    """A new, inactive version (activate() swaps it in)."""
    cur = conn.execute(
        "INSERT INTO vocabularies (path, created_at, trained_on, size, run, active, metadata)"
        " VALUES (?, ?, ?, ?, ?, 0, ?)",
        (path, created_at or utcnow(), trained_on, size, run, json.dumps(metadata)),
    )
    return int(cur.lastrowid or 0)


def set_path(conn: sqlite3.Connection, vocabulary_id: int, path: str) -> None:
    conn.execute("UPDATE vocabularies SET path = ? WHERE id = ?", (path, vocabulary_id))


def activate(conn: sqlite3.Connection, vocabulary_id: int) -> None:
    """Make `vocabulary_id` the one active version (call inside a write transaction)."""
    conn.execute("UPDATE vocabularies SET active = 0 WHERE active = 1")
    conn.execute("UPDATE vocabularies SET active = 1 WHERE id = ?", (vocabulary_id,))


def active(conn: sqlite3.Connection) -> VocabularyRecord | None:
    return _record(conn.execute("SELECT * FROM vocabularies WHERE active = 1").fetchone())


def get(conn: sqlite3.Connection, vocabulary_id: int) -> VocabularyRecord | None:
    return _record(conn.execute("SELECT * FROM vocabularies WHERE id = ?", (vocabulary_id,)).fetchone())


def delete_inactive(conn: sqlite3.Connection, vocabulary_ids: list[int]) -> list[int]:
    """Delete these versions, never the active one (their BoF rows go by ON DELETE CASCADE);
    returns the ids deleted."""
    sql = "DELETE FROM vocabularies WHERE id = ? AND active = 0"
    return [vid for vid in vocabulary_ids if conn.execute(sql, (vid,)).rowcount]


def all_versions(conn: sqlite3.Connection) -> list[VocabularyRecord]:
    return [_record(r) for r in conn.execute("SELECT * FROM vocabularies ORDER BY id")]  # type: ignore[misc]


# --- BoF vectors -------------------------------------------------------------------------------------------


def put_vector(conn: sqlite3.Connection, model_id: int, vocabulary_id: int, vector: np.ndarray) -> None:
    """Store (or replace, with a new seq so pollers see it) one model's BoF for one version."""
    blob = np.ascontiguousarray(vector, dtype=np.float32).tobytes()
    delete_vector(conn, model_id, vocabulary_id)
    conn.execute(
        "INSERT INTO bof (model_id, vocabulary_id, vector) VALUES (?, ?, ?)", (model_id, vocabulary_id, blob)
    )


def delete_vector(conn: sqlite3.Connection, model_id: int, vocabulary_id: int) -> None:
    """Drop one model's BoF for one version (the model stays; it has no vector there until encoded)."""
    conn.execute("DELETE FROM bof WHERE model_id = ? AND vocabulary_id = ?", (model_id, vocabulary_id))


def vectors(
    conn: sqlite3.Connection, vocabulary_id: int, after_seq: int = 0
) -> tuple[np.ndarray, np.ndarray, int]:
    """BoF vectors of ready models for one version with seq > after_seq.

    Returns ids (n,) int64, vectors (n, v) float32, and the highest seq seen (after_seq if none).
    """
    rows = conn.execute(
        "SELECT b.seq, b.model_id, b.vector FROM bof b JOIN models m ON m.id = b.model_id"
        " WHERE b.vocabulary_id = ? AND b.seq > ? AND m.status = 'ready' ORDER BY b.seq",
        (vocabulary_id, after_seq),
    ).fetchall()
    if not rows:
        return np.zeros(0, np.int64), np.zeros((0, 0), np.float32), after_seq
    ids = np.array([r["model_id"] for r in rows], dtype=np.int64)
    vecs = np.stack([np.frombuffer(r["vector"], dtype=np.float32) for r in rows])
    return ids, vecs, int(rows[-1]["seq"])


def vector_of(conn: sqlite3.Connection, model_id: int, vocabulary_id: int) -> np.ndarray | None:
    row = conn.execute(
        "SELECT vector FROM bof WHERE model_id = ? AND vocabulary_id = ?", (model_id, vocabulary_id)
    ).fetchone()
    return None if row is None else np.frombuffer(row[0], dtype=np.float32).copy()


def vectors_of(conn: sqlite3.Connection, vocabulary_id: int, model_ids: list[int]) -> dict[int, np.ndarray]:
    """The stored vectors of these models under one version (those it has), by model id."""
    if not model_ids:
        return {}
    marks = ",".join("?" * len(model_ids))
    rows = conn.execute(
        f"SELECT model_id, vector FROM bof WHERE vocabulary_id = ? AND model_id IN ({marks})",
        [vocabulary_id, *(int(i) for i in model_ids)],
    ).fetchall()
    return {int(r[0]): np.frombuffer(r[1], dtype=np.float32).copy() for r in rows}


def ready_without_vector(conn: sqlite3.Connection, vocabulary_id: int) -> list[int]:
    rows = conn.execute(
        "SELECT id FROM models WHERE status = 'ready' AND id NOT IN"
        " (SELECT model_id FROM bof WHERE vocabulary_id = ?) ORDER BY id",
        (vocabulary_id,),
    )
    return [r[0] for r in rows]


def max_seq(conn: sqlite3.Connection) -> int:
    return int(conn.execute("SELECT COALESCE(MAX(seq), 0) FROM bof").fetchone()[0])
