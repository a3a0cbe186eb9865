"""The query-adaptive fusion re-rank (app.core.fusion.adaptive_rerank) over the fused L1 index.

The index keeps ranking by the fixed fusion (BoF + w × Shape-DNA, each over its vocabulary scale); a
query then takes the union of two of its searches (the query's and the expanded query's CANDIDATES
nearest) and ranks it by its own weight (docs/results.md, issue 30). A hit's `distance` stays the
index's fused L1 distance from the query as sent (a stored copy of it is at 0, and explain decomposes
that number); the re-rank's own distance, which the hits are ordered by, comes beside it.
SHAPEBAG_FUSION_RERANK=false serves the index's order as it is; a vocabulary without fusion scales (pure
BoF) never re-ranks.
"""

from __future__ import annotations

import numpy as np

from app.core import fusion
from app.core.object_rows import merge_rows
from app.core.vocabulary import l1_distance
from app.services.context import ServiceContext
from app.services.errors import NotReadyError
from app.services.live_index import LiveIndex
from app.storage import vocabularies as vocab_repo

CANDIDATES = fusion.RERANK_CANDIDATES  # each of the two searches; >= search.MAX_K
RULE = fusion.AdaptiveRule()


def applies(ctx: ServiceContext, live: LiveIndex) -> bool:
    """Whether the active pair's vectors are fused (a Shape-DNA part with a weight) and re-ranking is on."""
    pair = live.pair
    if not ctx.settings.fusion_rerank or pair is None or not pair.params.fusion:
        return False
    scales = pair.vocabulary.fusion
    return scales is not None and scales.weight > 0


def search(
    ctx: ServiceContext, live: LiveIndex, vector: np.ndarray, k: int, allowed: np.ndarray | None,
    vocabulary_id: int, exclude: int | None = None, rim: float | None = None, noise: float | None = None,
) -> tuple[np.ndarray, np.ndarray, int, np.ndarray, np.ndarray]:
    """vector (v + c,) fused -> the index's fused L1 distances (<= k,) of the ids (<= k,) in re-ranked
    order, the version that answered, the re-rank's distances (<= k,, ascending), and the row of each
    model that matched (<= k,: 0 its whole, p > 0 its object row p; services/object_rows).
    `exclude`: a stored model left out (the one whose neighbours are asked); `rim`: the query's free
    boundary over √area (None: unknown, weighed as an open surface); `noise`: its input's displacement
    correlation (None or NaN: unknown, weighed as clean). A model is a candidate through its nearest
    row (whole or object), and the re-rank reads that row's vector."""
    pair = live.require()
    if pair.record.id != vocabulary_id or pair.vocabulary.fusion is None:
        raise NotReadyError("the vocabulary changed while the query was encoded; retry")
    scales = pair.vocabulary.fusion

    parts: dict[int, int] = {}  # each candidate's row, the first search's nearest

    def nearest(v: np.ndarray, n: int) -> np.ndarray:
        dist, ids, _ = live.search(v, n + (exclude is not None), allowed, vocabulary_id=vocabulary_id)
        rows = live.search_objects(v, n + (exclude is not None), allowed, vocabulary_id=vocabulary_id)
        _, ids, found = merge_rows(dist, ids, *rows)
        for i, part in zip(ids, found, strict=True):
            parts.setdefault(int(i), int(part))
        return ids[ids != exclude][:n]

    seen: dict[int, np.ndarray] = {}  # every candidate's stored vector, read once

    def vectors_of(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with ctx.db.read() as conn:
            found = vocab_repo.vectors_of(conn, vocabulary_id, [int(i) for i in ids if int(i) not in seen])
        seen.update(found)
        for i in ids:  # a candidate through an object row is compared as that object
            part = parts.get(int(i), 0)
            row = live.object_vector(int(i), part) if part and int(i) in seen else None
            if row is not None:
                seen[int(i)] = row
        found = {int(i): seen[int(i)] for i in ids if int(i) in seen}
        kept = np.array([i for i in ids if int(i) in found], np.int64)  # deleted a moment ago: dropped
        rows = [found[int(i)] for i in kept]
        return kept, (np.stack(rows) if rows else np.zeros((0, len(vector)), np.float32))

    ids, dist = fusion.adaptive_rerank(vector, nearest, vectors_of, pair.vocabulary.size, scales.weight, RULE,
                                       max(CANDIDATES, k), rim, noise)
    ids, dist = ids[:k], dist[:k]
    stored = np.stack([seen[int(i)] for i in ids]) if len(ids) else np.zeros((0, len(vector)), np.float32)
    index_distance = l1_distance(stored, vector[None])[:, 0]  # the query as sent: what the index ranks by
    matched = np.array([parts.get(int(i), 0) for i in ids], np.int64)
    return index_distance.astype(np.float32), ids, vocabulary_id, dist.astype(np.float32), matched

