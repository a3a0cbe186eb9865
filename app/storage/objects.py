"""Repository of object rows: the distinct objects of multi-object files (`model_objects`) and their BoF
vectors per vocabulary version (`object_bof`). Both go with their model (ON DELETE CASCADE) and the
vectors with their version. A row's index id is row_id(model, part) (app.core.object_rows)."""

from __future__ import annotations

import sqlite3

import numpy as np

PART_BITS = 8  # parts 1..255 (app.core.object_rows.MAX_ROWS is far below)


def row_id(model_id: int, part: int) -> int:
    """The index id of one object row: model ids stay far below 2^55 (AUTOINCREMENT from 1)."""
    return (int(model_id) << PART_BITS) | int(part)


def split_row_ids(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index ids (n,) int64 -> model ids (n,), parts (n,)."""
    ids = np.asarray(ids, np.int64)
    return ids >> PART_BITS, ids & ((1 << PART_BITS) - 1)


def put_objects(conn: sqlite3.Connection, model_id: int, rows: list[tuple[int, int, float]]) -> None:
    """Replace a model's objects: (part, copies, share) each."""
    conn.execute("DELETE FROM model_objects WHERE model_id = ?", (model_id,))
    for part, copies, share in rows:
        conn.execute(
            "INSERT INTO model_objects (model_id, part, copies, share) VALUES (?, ?, ?, ?)",
            (model_id, int(part), int(copies), float(share)),
        )


def objects_of(conn: sqlite3.Connection, model_id: int) -> list[tuple[int, int, float]]:
    """(part, copies, share) of one model's object rows, by part."""
    rows = conn.execute(
        "SELECT part, copies, share FROM model_objects WHERE model_id = ? ORDER BY part", (model_id,)
    )
    return [(int(r[0]), int(r[1]), float(r[2])) for r in rows]


def ready_parts(conn: sqlite3.Connection) -> list[tuple[int, int]]:
    """(model id, part) of the object rows of ready models, in order."""
    rows = conn.execute(
        "SELECT o.model_id, o.part FROM model_objects o JOIN models m ON m.id = o.model_id"
        " WHERE m.status = 'ready' ORDER BY o.model_id, o.part"
    )
    return [(int(r[0]), int(r[1])) for r in rows]


def parts_without_vector(conn: sqlite3.Connection, vocabulary_id: int) -> list[tuple[int, int]]:
    """(model id, part) of ready models' object rows that have no vector under this version."""
    rows = conn.execute(
        "SELECT o.model_id, o.part FROM model_objects o JOIN models m ON m.id = o.model_id"
        " WHERE m.status = 'ready' AND NOT EXISTS (SELECT 1 FROM object_bof b WHERE b.model_id = o.model_id"
        " AND b.part = o.part AND b.vocabulary_id = ?) ORDER BY o.model_id, o.part",
        (vocabulary_id,),
    )
    return [(int(r[0]), int(r[1])) for r in rows]


def put_vector(conn: sqlite3.Connection, model_id: int, part: int, vocabulary_id: int,
               vector: np.ndarray) -> None:
    """Store (or replace, with a new seq so pollers see it) one object row's vector for one version."""
    blob = np.ascontiguousarray(vector, dtype=np.float32).tobytes()
    conn.execute(
        "DELETE FROM object_bof WHERE model_id = ? AND part = ? AND vocabulary_id = ?",
        (model_id, part, vocabulary_id),
    )
    conn.execute(
        "INSERT INTO object_bof (model_id, part, vocabulary_id, vector) VALUES (?, ?, ?, ?)",
        (model_id, part, vocabulary_id, blob),
    )


def delete_vectors(conn: sqlite3.Connection, model_id: int, vocabulary_id: int) -> None:
    conn.execute("DELETE FROM object_bof WHERE model_id = ? AND vocabulary_id = ?", (model_id, vocabulary_id))


def vectors(
    conn: sqlite3.Connection, vocabulary_id: int, after_seq: int = 0
) -> tuple[np.ndarray, np.ndarray, int]:
    """Object rows of ready models under one version with seq > after_seq.

    Returns row ids (n,) int64 (row_id), vectors (n, v) float32, and the highest seq seen (after_seq if
    none)."""
    rows = conn.execute(
        "SELECT b.seq, b.model_id, b.part, b.vector FROM object_bof b JOIN models m ON m.id = b.model_id"
        " WHERE b.vocabulary_id = ? AND b.seq > ? AND m.status = 'ready' ORDER BY b.seq",
        (vocabulary_id, after_seq),
    ).fetchall()
    if not rows:
        return np.zeros(0, np.int64), np.zeros((0, 0), np.float32), after_seq
    ids = np.array([row_id(r[1], r[2]) for r in rows], dtype=np.int64)
    vecs = np.stack([np.frombuffer(r[3], dtype=np.float32) for r in rows])
    return ids, vecs, int(rows[-1][0])
