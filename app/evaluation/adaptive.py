"""The query-adaptive fusion re-rank (app.core.fusion.adaptive_rerank) scored as the service runs it.

The index is brute-force L1 over the fused vectors here (what FAISS's flat METRIC_L1 index returns), so
a line scored with `ranks` is the served ranking of its first `candidates` results; the shapes outside
the union of the re-rank's two searches follow in the fixed fusion's order (the service never returns
them: k <= app.services.search.MAX_K <= candidates). Given the local signatures, a query with a rim (a
piece, an open scan) is ranked instead as the service ranks a piece (app.core.piece_rank), with no
deadline.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from app.core import fusion, piece_rank
from app.core.partial import LocalSignature
from app.core.pipeline import LOCAL, ShapeDescription

CANDIDATES = fusion.RERANK_CANDIDATES  # each of the re-rank's two index searches, as served


def ranks(
    queries: np.ndarray, db: np.ndarray, left_out: np.ndarray, words: int, stored_weight: float,
    rule: fusion.AdaptiveRule | None = None, candidates: int = CANDIDATES, rims: np.ndarray | None = None,
    noises: np.ndarray | None = None, query_locals: Sequence[LocalSignature | None] | None = None,
    db_locals: Sequence[LocalSignature | None] | None = None,
) -> np.ndarray:
    """queries (q, v + c), db (N, v + c) fused vectors; left_out (q,) the database index each query must
    not see (its own or clean copy), or -1; rims (q,) each query's rim (NaN or None: unknown), noises (q,)
    each query's input displacement correlation (NaN or None: unknown) -> (q, N)
    float64 rank of each shape in each query's list (the left-out shape last), usable as a distance
    matrix by app.core.metrics and evaluation.sets. With query_locals (q,) and db_locals (N,), the local
    signatures, a query with a rim is ranked as the service ranks a piece (app.core.piece_rank, with no
    deadline: its candidates by partial score, then the global order)."""
    rule = rule or fusion.AdaptiveRule()
    db = np.asarray(db, dtype=np.float32)
    out = np.empty((len(queries), len(db)))
    for i, query in enumerate(np.asarray(queries, dtype=np.float32)):
        skip = int(left_out[i])

        def search(vector: np.ndarray, n: int, skip: int = skip) -> np.ndarray:
            d = np.abs(db - vector).sum(axis=1, dtype=np.float64)
            if skip >= 0:
                d[skip] = np.inf
            near = np.argsort(d, kind="stable")[:n]
            return near[np.isfinite(d[near])]

        local = None if query_locals is None else query_locals[i]
        if db_locals is not None and local is not None and piece_rank.is_piece(local):
            fixed = np.abs(db - query).sum(axis=1, dtype=np.float64)
            if skip >= 0:
                fixed[skip] = np.inf
            order = np.argsort(fixed, kind="stable")
            order = order[np.isfinite(fixed[order])]  # the left-out shape: last, below
            served_order = piece_rank.piece_order(local, order, db_locals.__getitem__, LOCAL, vectors=db)
            out[i, np.concatenate([served_order, np.setdiff1d(np.arange(len(db)), served_order)])] = (
                np.arange(len(db)))
            continue
        rim = None if rims is None else float(rims[i])
        noise = None if noises is None else float(noises[i])
        ids, _ = fusion.adaptive_rerank(query, search, lambda j: (j, db[j]), words, stored_weight, rule,
                                        candidates, rim, noise)
        served = np.abs(db - query).sum(axis=1, dtype=np.float64)
        if skip >= 0:
            served[skip] = np.inf
        rest = np.setdiff1d(np.argsort(served, kind="stable"), ids, assume_unique=True)
        out[i, np.concatenate([ids, rest])] = np.arange(len(db))
    return out


def rims_of(descriptions: list[ShapeDescription]) -> np.ndarray:
    """(n,) each description's rim (free boundary over √area), NaN where it has no local signature."""
    return np.array([np.nan if d.local is None else float(d.local.rim) for d in descriptions])


def noises_of(descriptions: list[ShapeDescription]) -> np.ndarray:
    """(n,) each description's input displacement correlation, NaN where it was saved without one."""
    return np.array([float(d.input_noise) for d in descriptions])
