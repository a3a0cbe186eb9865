"""Repository of variant data: fingerprints per model (and per object), verified relations, and
reviewers' decisions (appended, never updated or removed: the latest one per pair is the answer)."""

from __future__ import annotations

import json
import sqlite3

import numpy as np

from app.storage.db import utcnow


def put_fingerprints(conn: sqlite3.Connection, model_id: int, version: int, vectors: np.ndarray) -> None:
    """vectors (parts, DIM) float32: row 0 the whole model, then its objects; replaces older ones."""
    conn.execute("DELETE FROM fingerprints WHERE model_id = ?", (model_id,))
    for part, v in enumerate(np.asarray(vectors, np.float32)):
        conn.execute(
            "INSERT INTO fingerprints (model_id, part, version, vector) VALUES (?, ?, ?, ?)",
            (model_id, part, version, v.tobytes()),
        )


def fingerprints_since(
    conn: sqlite3.Connection, after_seq: int, version: int, dim: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """(model ids (n,), vectors (n, dim) float32, highest seq seen) of rows with seq > after_seq."""
    rows = conn.execute(
        "SELECT seq, model_id, vector FROM fingerprints WHERE seq > ? AND version = ? ORDER BY seq",
        (after_seq, version),
    ).fetchall()
    if not rows:
        return np.zeros(0, np.int64), np.zeros((0, dim), np.float32), after_seq
    ids = np.array([r[1] for r in rows], np.int64)
    vectors = np.stack([np.frombuffer(bytes(r[2]), np.float32) for r in rows])
    return ids, vectors, int(rows[-1][0])


def ready_without_fingerprints(conn: sqlite3.Connection, version: int) -> list[int]:
    """Ready models with no fingerprint of this recipe version (stored before the variant step, or
    under an older recipe), oldest first."""
    rows = conn.execute(
        "SELECT id FROM models WHERE status = 'ready' AND NOT EXISTS (SELECT 1 FROM fingerprints f"
        " WHERE f.model_id = models.id AND f.version = ?) ORDER BY id",
        (version,),
    ).fetchall()
    return [int(r[0]) for r in rows]


def put_link(
    conn: sqlite3.Connection, model_id: int, other_id: int, relation: str, confidence: float, evidence: dict
) -> None:
    conn.execute(
        "INSERT INTO variant_links (model_id, other_id, relation, confidence, evidence, created_at)"
        " VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT (model_id, other_id) DO UPDATE SET"
        " relation = excluded.relation, confidence = excluded.confidence, evidence = excluded.evidence,"
        " created_at = excluded.created_at",
        (model_id, other_id, relation, float(confidence), json.dumps(evidence, allow_nan=False), utcnow()),
    )


def links_of(conn: sqlite3.Connection, model_id: int) -> list[dict]:
    """Every stored relation touching the model: {model_id, other_id, relation, confidence, evidence}."""
    rows = conn.execute(
        "SELECT model_id, other_id, relation, confidence, evidence, created_at FROM variant_links"
        " WHERE model_id = ? OR other_id = ? ORDER BY confidence DESC, other_id",
        (model_id, model_id),
    ).fetchall()
    return [
        {"model_id": r[0], "other_id": r[1], "relation": r[2], "confidence": float(r[3]),
         "evidence": json.loads(r[4]), "created_at": r[5]}
        for r in rows
    ]


KEPT_DECISIONS = 10  # the latest decisions of one pair kept: a history, not an unbounded log


def add_decision(conn: sqlite3.Connection, a: int, b: int, decision: str, note: str | None) -> str:
    """Append a reviewer's decision about the pair (either order), keeping the pair's latest
    KEPT_DECISIONS (a flood of decisions once grew the database by 574 rows a second and every
    model page's read with it); returns its time."""
    now = utcnow()
    low, high = min(a, b), max(a, b)
    conn.execute(
        "INSERT INTO variant_decisions (low_id, high_id, decision, note, created_at) VALUES (?, ?, ?, ?, ?)",
        (low, high, decision, note, now),
    )
    conn.execute(
        "DELETE FROM variant_decisions WHERE low_id = ? AND high_id = ? AND seq NOT IN"
        " (SELECT seq FROM variant_decisions WHERE low_id = ? AND high_id = ? ORDER BY seq DESC LIMIT ?)",
        (low, high, low, high, KEPT_DECISIONS),
    )
    return now


def decisions_of(conn: sqlite3.Connection, model_id: int) -> dict[int, dict]:
    """The latest decision per other model: {other id: {decision, note, created_at}}."""
    rows = conn.execute(
        "SELECT low_id, high_id, decision, note, created_at FROM variant_decisions"
        " WHERE low_id = ? OR high_id = ? ORDER BY seq",
        (model_id, model_id),
    ).fetchall()
    out: dict[int, dict] = {}
    for low, high, decision, note, created in rows:
        other = int(high if low == model_id else low)
        out[other] = {"decision": decision, "note": note, "decided_at": created}
    return out
