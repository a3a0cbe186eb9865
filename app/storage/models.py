"""Repository of uploaded models (the `models` table)."""

from __future__ import annotations

import json
import sqlite3
from dataclasses import dataclass, field

from app.storage.db import utcnow


@dataclass(frozen=True)
class ModelRecord:
    id: int
    name: str
    label: str | None
    sha256: str
    file_type: str
    size_bytes: int
    status: str
    error: str | None
    n_vertices: int | None
    created_at: str
    updated_at: str
    metadata: dict = field(default_factory=dict)


def _record(row: sqlite3.Row | None) -> ModelRecord | None:
    if row is None:
        return None
    d = dict(row)
    d["metadata"] = _metadata(d["metadata"])
    return ModelRecord(**d)


def _metadata(text: str | None) -> dict:
    """The stored metadata, or a placeholder when a row written before metadata was validated holds
    something standard JSON cannot carry (NaN, a lone surrogate...): every read must serialise."""
    try:
        value = json.loads(text or "{}", parse_constant=_refuse_constant)
        json.dumps(value, allow_nan=False, ensure_ascii=False).encode("utf-8")
        if _depth(value) > MAX_READ_DEPTH:
            raise ValueError("nested too deep")
    except (ValueError, RecursionError, UnicodeEncodeError):
        return {"unreadable": "the stored metadata is not standard JSON; upload the model again to fix it"}
    return value if isinstance(value, dict) else {}


MAX_READ_DEPTH = 64  # pydantic's serialiser gives up (500) well before json does


def _depth(value: object) -> int:
    if isinstance(value, dict):
        return 1 + max((_depth(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_depth(v) for v in value), default=0)
    return 0


def _refuse_constant(name: str) -> None:
    raise ValueError(f"{name} is not standard JSON")


def insert(
    conn: sqlite3.Connection,
    *,
    name: str,
    label: str | None,
    metadata: dict,
    sha256: str,
    file_type: str,
    size_bytes: int,
) -> int:
    now = utcnow()
    cur = conn.execute(
        "INSERT INTO models (name, label, metadata, sha256, file_type, size_bytes, status,"
        " created_at, updated_at)"
        " VALUES (?, ?, ?, ?, ?, ?, 'queued', ?, ?)",
        (name, label, json.dumps(metadata, allow_nan=False), sha256, file_type, size_bytes, now, now),
    )
    return int(cur.lastrowid or 0)


def get(conn: sqlite3.Connection, model_id: int) -> ModelRecord | None:
    return _record(conn.execute("SELECT * FROM models WHERE id = ?", (model_id,)).fetchone())


def get_by_sha256(conn: sqlite3.Connection, sha256: str) -> ModelRecord | None:
    return _record(conn.execute("SELECT * FROM models WHERE sha256 = ?", (sha256,)).fetchone())


def get_many(conn: sqlite3.Connection, ids: list[int]) -> dict[int, ModelRecord]:
    if not ids:
        return {}
    marks = ",".join("?" * len(ids))
    rows = conn.execute(f"SELECT * FROM models WHERE id IN ({marks})", [int(i) for i in ids]).fetchall()
    return {r["id"]: _record(r) for r in rows}  # type: ignore[misc]


def page(
    conn: sqlite3.Connection,
    *,
    label: str | None = None,
    status: str | None = None,
    limit: int = 50,
    offset: int = 0,
) -> tuple[list[ModelRecord], int]:
    """One page of models (newest first) and the total matching the filters."""
    where, args = [], []
    if label is not None:
        where.append("label = ?")
        args.append(label)
    if status is not None:
        where.append("status = ?")
        args.append(status)
    clause = f"WHERE {' AND '.join(where)}" if where else ""
    total = conn.execute(f"SELECT COUNT(*) FROM models {clause}", args).fetchone()[0]
    rows = conn.execute(
        f"SELECT * FROM models {clause} ORDER BY id DESC LIMIT ? OFFSET ?", [*args, limit, offset]
    ).fetchall()
    return [_record(r) for r in rows], int(total)  # type: ignore[misc]


def set_ready(conn: sqlite3.Connection, model_id: int, n_vertices: int) -> None:
    conn.execute(
        "UPDATE models SET status = 'ready', error = NULL, n_vertices = ?, updated_at = ? WHERE id = ?",
        (n_vertices, utcnow(), model_id),
    )


def set_failed(conn: sqlite3.Connection, model_id: int, error: str) -> None:
    conn.execute(
        "UPDATE models SET status = 'failed', error = ?, updated_at = ? WHERE id = ?",
        (error, utcnow(), model_id),
    )


def set_queued(conn: sqlite3.Connection, model_id: int) -> None:
    conn.execute(
        "UPDATE models SET status = 'queued', error = NULL, updated_at = ? WHERE id = ?", (utcnow(), model_id)
    )


def delete(conn: sqlite3.Connection, model_id: int) -> None:
    """Delete the row (its BoF vectors cascade) and log the id for other replicas (deleted_since)."""
    if conn.execute("DELETE FROM models WHERE id = ?", (model_id,)).rowcount:
        conn.execute("INSERT INTO deletions (model_id) VALUES (?)", (model_id,))


def deleted_since(conn: sqlite3.Connection, after_seq: int) -> tuple[list[int], int]:
    """Model ids deleted with seq > after_seq, and the highest seq seen (after_seq if none)."""
    rows = conn.execute(
        "SELECT seq, model_id FROM deletions WHERE seq > ? ORDER BY seq", (after_seq,)
    ).fetchall()
    return [int(r[1]) for r in rows], int(rows[-1][0]) if rows else after_seq


def ids_with_label(conn: sqlite3.Connection, label: str) -> list[int]:
    return [
        r[0] for r in conn.execute("SELECT id FROM models WHERE label = ? AND status = 'ready'", (label,))
    ]


def ready_ids(conn: sqlite3.Connection) -> list[int]:
    return [r[0] for r in conn.execute("SELECT id FROM models WHERE status = 'ready' ORDER BY id")]


def label_counts(conn: sqlite3.Connection) -> list[tuple[str, int]]:
    """(label, models) for every label in use, by name (the models_label index serves the GROUP BY)."""
    rows = conn.execute(
        "SELECT label, COUNT(*) FROM models WHERE label IS NOT NULL AND label != ''"
        " GROUP BY label ORDER BY label"
    )
    return [(str(label), int(n)) for label, n in rows]


def count_by_status(conn: sqlite3.Connection) -> dict[str, int]:
    counts = {"queued": 0, "ready": 0, "failed": 0}
    for status, n in conn.execute("SELECT status, COUNT(*) FROM models GROUP BY status"):
        counts[status] = int(n)
    return counts
