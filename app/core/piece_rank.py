"""How a piece's search orders a collection: its candidates, their partial scores, the order (pure).

A query whose rim (app.core.partial.rim_length) is at least RIM_PARTIAL is taken for a piece. Its
candidates are the first GLOBAL_KEEP models of the global order and the COARSE_KEEP nearest by a coarse
partial distance (the query's first COARSE_POINTS samples) among the first COARSE_SCAN; each candidate
is scored (match_many, then the vote among the candidates scored, then each score averaged with its
nearest fellow candidates': with_peers) and the candidates come first by score, past the first page
anchored on the first hit (by_score: their whole-shape distance to it counts too), the models without
a score after them in their global order. The service
(app.services.partial) runs these steps with the signatures read lazily and a deadline on each pass;
the evaluation (app.evaluation.adaptive) runs them whole, through `piece_order`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from scipy.spatial.distance import cdist

from app.core import piece_fit
from app.core.partial import LocalParams, LocalSignature
from app.core.partial_match import (
    CAP,
    COPY_DISTANCE,
    PEER_RADIUS,
    PEERS,
    PartialMatch,
    head,
    match_many,
    votes,
)

# whole SHREC'11 meshes have no rim (0.0); their 40-85 % pieces at least 0.26 (docs/partial.md)
RIM_PARTIAL = 0.2
# a piece's candidates (docs/partial.md): global top 100 + coarse top 100 took SHREC'11's 60-85 %
# pieces from 76.9 (global top 200) to 82.9 mAP on a sample of 100, for the same 200 full matches
GLOBAL_KEEP = 100
COARSE_KEEP = 100
COARSE_POINTS = 32  # an eighth of the samples: an eighth of a full match's cost per model
COARSE_SCAN = 2000  # models the coarse pass reads, nearest first: all of a collection of this size
# past its first PAGE candidates the order is anchored on its first hit (by_score): the others'
# whole-shape distance to it, over the median such distance, weighs this many CAPs (SHREC'11's picking
# split: 0.1-1.0 within 1.2 mAP of each other on every set, docs/partial.md)
ANCHOR = 0.25
PAGE = 10  # the first page of a piece's hits is ordered by the scores alone


def is_piece(query: LocalSignature | None, requested: bool | None = None) -> bool:
    """The caller's choice when given, else whether the query has a rim."""
    if requested is not None:
        return requested
    return query is not None and query.rim >= RIM_PARTIAL


def chosen(n: int, coarse: Sequence[PartialMatch | None], keep: int = GLOBAL_KEEP,
           coarse_keep: int = COARSE_KEEP) -> list[int]:
    """Indices into a global order of n models, in that order: the first `keep`, and the `coarse_keep`
    with the smallest coarse distance (coarse: one match or None per model of the order's head)."""
    scored = sorted((m.distance, j) for j, m in enumerate(coarse) if m is not None)
    return sorted(set(range(min(keep, n))) | {j for _, j in scored[:coarse_keep]})


def voted(query: LocalSignature, found: Sequence[PartialMatch | None],
          params: LocalParams) -> list[PartialMatch | None]:
    """The matches with their vote share among the candidates scored (the score reads it)."""
    scored = [(j, m) for j, m in enumerate(found) if m is not None]
    shares = votes(query, [m for _, m in scored], params)
    out = list(found)
    for (j, m), share in zip(scored, shares, strict=True):
        out[j] = replace(m, vote=float(share))
    return out


def with_peers(found: Sequence[PartialMatch | None], vectors: np.ndarray, count: int = PEERS,
               radius: float | None = None) -> list[PartialMatch | None]:
    """The matches with `peers` set: the mean own score of each one's `count` nearest fellow scored
    candidates by L1 between their stored global vectors (the index's metric), of those within
    `radius` of it (None: PEER_RADIUS); a match with none that near keeps its own score. A match
    within COPY_DISTANCE of the query is a stored copy of it and nobody's peer: its score of about 0
    would pull its neighbours ahead of the piece's source, whatever their class.

    found   : one match (None: unscored) per candidate
    vectors : (n, d) the candidates' stored fused vectors, a row of NaN where unknown (such a candidate
              keeps its own score and is nobody's peer)
    Why: the models of a piece's source class are near each other in the global space and all cover
    the piece, so their scores agree; a model of another class that resembles one part of the piece
    scores well alone among its neighbours (+3.4 to +4.2 mAP on SHREC'11's held-out pieces,
    docs/partial.md)."""
    vectors = np.asarray(vectors, dtype=np.float64)
    if vectors.shape[0] != len(found):
        raise ValueError(f"{len(found)} matches but {vectors.shape[0]} vectors")
    scored = [(j, m) for j, m in enumerate(found) if m is not None and bool(np.isfinite(vectors[j]).all())]
    out = list(found)
    if len(scored) < 2 or count < 1:
        return out
    radius = PEER_RADIUS if radius is None else radius
    own = np.array([m.own for _, m in scored])
    rows = vectors[[j for j, _ in scored]]
    dist = cdist(rows, rows, metric="cityblock")
    np.fill_diagonal(dist, np.inf)
    dist[:, [m.distance <= COPY_DISTANCE for _, m in scored]] = np.inf  # a copy of the query: no peer
    near = np.argsort(dist, axis=1, kind="stable")[:, :min(count, len(scored) - 1)]  # (c, count)
    close = np.take_along_axis(dist, near, axis=1) <= radius
    for (j, m), peers, ok in zip(scored, own[near], close, strict=True):
        if ok.any():
            out[j] = replace(m, peers=float(peers[ok].mean()))
    return out


def by_score(found: Sequence[PartialMatch | None], vectors: np.ndarray | None = None,
             anchor: float | None = None, page: int | None = None, lead: Sequence[int] = ()) -> list[int]:
    """Indices of `found` (candidates in global order) by score, the unscored last in their order.

    vectors (n, d): the candidates' stored fused vectors (a row of NaN where unknown), given to anchor
    the order beyond its first page on its first hit: the first `page` (None: PAGE) candidates stay
    in score order, and every later one is ordered by its score plus `anchor` (None: ANCHOR) x CAP x
    its L1 distance to the first hit (the best-scored candidate that is not a stored copy of the
    query) over the median such distance (a candidate of unknown vector: the median). Why: whole
    shapes are compared reliably by their global vectors (SHREC'11 whole queries: 99 mAP), so past the
    first page the first hit's class-mates come before look-alikes of one part (held-out SHREC'11
    pieces +0.8 to +2.3 mAP); the first page is left to the scores because, when the first hit is
    wrong, anchoring it too would fill the page with the wrong class (the right class in the first 10
    for 0.79 of the pieces instead of 0.85; docs/partial.md).
    lead: candidates shown to contain the piece (app.core.piece_fit), in their order: they come first,
    the first of them is the anchor, and the page after them is anchored too (a fit is evidence, not
    a score: its class-mates follow it)."""
    rank = np.array([m.score if m is not None else np.inf for m in found], dtype=np.float64)
    lead = [j for j in dict.fromkeys(lead) if found[j] is not None]
    leading = set(lead)
    order = lead + [j for j in sorted(range(len(found)), key=lambda j: (rank[j], j)) if j not in leading]
    # a stored copy of the query leads (it lies on itself) but anchors nothing: its global vector is
    # the piece's own, which is what a piece's whole-shape distance cannot be trusted on; with no other
    # fit the first page is the scores' as before
    real = [j for j in lead if found[j].distance > COPY_DISTANCE]  # type: ignore[union-attr]
    page = (len(lead) if real else max(PAGE, len(lead))) if page is None else page
    if vectors is None or len(found) <= page:
        return order
    first = real[0] if real else _anchor(found, rank)
    if first is None:
        return order
    rest = order[page:]
    anchored = rank + _anchor_term(np.asarray(vectors, dtype=np.float64), first,
                                   ANCHOR if anchor is None else anchor)
    return order[:page] + sorted(rest, key=lambda j: (anchored[j], j))


def _anchor(found: Sequence[PartialMatch | None], rank: np.ndarray) -> int | None:
    """The best-scored candidate that is not a stored copy of the query (None: no such one)."""
    real = [j for j, m in enumerate(found) if m is not None and m.distance > COPY_DISTANCE]
    return min(real, key=lambda j: (rank[j], j)) if real else None


def _anchor_term(vectors: np.ndarray, first: int, weight: float) -> np.ndarray:
    """(n,) weight x CAP x each candidate's L1 distance to candidate `first` over the median such
    distance (the median where either vector is unknown; 0 when all are)."""
    if not np.isfinite(vectors[first]).all():
        return np.zeros(len(vectors))
    dist = np.abs(vectors - vectors[first]).sum(axis=1)
    known = np.isfinite(dist)
    known[first] = False
    scale = float(np.median(dist[known])) if known.any() else 0.0
    if scale <= 0.0:
        return np.zeros(len(vectors))
    dist = np.where(np.isfinite(dist), dist, scale)
    return weight * CAP * dist / scale


def piece_order(query: LocalSignature, order: np.ndarray,
                signature_of: Callable[[int], LocalSignature | None], params: LocalParams,
                keep: int = GLOBAL_KEEP, coarse_keep: int = COARSE_KEEP,
                vectors: np.ndarray | None = None) -> np.ndarray:
    """The ranking a piece's search serves, with no deadline: order (N,) the collection's indices in
    the global order -> (N,) the candidates by score, then every other model in the global order.
    signature_of(index): that model's local signature (None: it has none); keep, coarse_keep: as
    chosen(); vectors (N, d): the collection's stored fused vectors, by index, for with_peers (None:
    no peers, each candidate's own score)."""
    def matches(q: LocalSignature, indices: np.ndarray) -> list[PartialMatch | None]:
        sigs = [signature_of(int(i)) for i in indices]
        have = [(j, s) for j, s in enumerate(sigs) if s is not None]
        found = match_many(q, [s for _, s in have], params) if have else []
        out: list[PartialMatch | None] = [None] * len(sigs)
        for (j, _), m in zip(have, found, strict=True):
            out[j] = m
        return out

    coarse = [] if len(order) <= keep else matches(head(query, COARSE_POINTS), order[:COARSE_SCAN])
    first = chosen(len(order), coarse, keep, coarse_keep)
    candidates = order[first]
    found = voted(query, matches(query, candidates), params)
    held = None if vectors is None else np.asarray(vectors)[candidates]
    if held is not None:
        found = with_peers(found, held)
    fits = piece_fit.fitted(query, [signature_of(int(i)) for i in candidates], found, params).fits
    ranked = candidates[by_score(found, held, lead=piece_fit.leading(fits))]
    return np.concatenate([ranked, order[~np.isin(order, ranked)]])
