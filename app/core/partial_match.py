"""A query piece against models, by local signatures (app.core.partial): distance, forward, reverse.

For each scale hypothesis (a shift of the query's grid) every trusted query sample finds its nearest
sample in each model, in slope space (mean squared difference over the slopes the rim leaves it). Per
model, the hypothesis with the smallest area-weighted mean of these (each capped, so a part the model
lacks costs a bounded amount) wins; under it
- forward = the share of the query's trusted area whose nearest model sample is within `tolerance`;
- reverse = forward x the kept share that the winning scale implies (ratio^-shift, the shift refined
  between grid steps by a parabola through the scores): the area of the model the matched part of the
  query stands for, over the model's area. Counting the model samples that some query sample matches
  would count both legs for one (the slopes are the same on symmetric parts); the scale does not.
The score ranks candidates: the distance less MUTUAL x CAP x the mutual share, the query's trusted area
whose nearest model sample has it as its own nearest query sample at the winning scale (a one-to-one
match: a model whose samples look like many parts of the query, a spider's legs for an octopus's, draws
many query samples to few of its own; measured in docs/partial.md).
Forward and reverse are what a user reads, and `region` where: the share
of the query's area each model sample matches under the winning scale (what the page's 3D view colours).
`head` keeps a signature's first samples: a coarser farthest-point sample of the same shape, for a cheap
first pass over many models.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from app.core.partial import LocalParams, LocalSignature

MIN_SLOPES = 4  # a sample with fewer trusted slopes than this sits on the rim: it is not compared
TOLERANCE = 2e-3  # mean squared slope difference under which two samples match
CAP = 4 * TOLERANCE  # one unmatched sample costs at most this: a missing part does not swamp the rest
MUTUAL = 1.0  # weight of the mutual share in the score, in CAPs (0.5-4 gained alike: docs/partial.md)


@dataclass(frozen=True)
class PartialMatch:
    distance: float  # area-weighted mean over query samples of min(nearest squared distance, CAP)
    forward: float  # in [0, 1]
    reverse: float  # in [0, 1]
    scale: float  # kept share the winning scale implies (1: the query is as large as the model)
    shift: int = 0  # the winning scale hypothesis (the query grid's window), which `region` reads
    mutual: float = 0.0  # the query's trusted area matched one-to-one at that scale (match_many(mutual=True))

    @property
    def score(self) -> float:
        """What a re-ranking orders by, lower first: the distance less the mutual share's weight."""
        return self.distance - MUTUAL * CAP * self.mutual


@dataclass(frozen=True)
class Region:
    """Where a query matched in one model, per model sample.

    vertex : (p,) int32, the model's sample vertices (LocalSignature.vertex)
    weight : (p,) float64, the share of the query's trusted area whose nearest model sample this is,
             within the tolerance (sums to the match's forward score; 0 where nothing matched)
    """

    vertex: np.ndarray
    weight: np.ndarray


def head(signature: LocalSignature, count: int) -> LocalSignature:
    """The first `count` samples of a signature: local_signature stores them in farthest-point order,
    so they are a coarser farthest-point sample of the same surface (their areas are renormalised by
    match_many over the trusted ones)."""
    vertex = None if signature.vertex is None else signature.vertex[:count]
    return LocalSignature(slopes=signature.slopes[:count], area=signature.area[:count],
                          valid=signature.valid[:count], rim=signature.rim, vertex=vertex)


def _sq_distances(q: np.ndarray, qvalid: np.ndarray, m: np.ndarray) -> np.ndarray:
    """(p, s) mean squared difference over each query sample's trusted leading slopes.

    q (p, J), qvalid (p,) in [MIN_SLOPES, J], m (s, J)."""
    out = np.empty((len(q), len(m)))
    for length in np.unique(qvalid):
        rows = qvalid == length
        a, b = q[rows, :length].astype(np.float64), m[:, :length].astype(np.float64)
        d = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
        out[rows] = np.maximum(d, 0.0) / length
    return out


def _refine(scores: np.ndarray, best: np.ndarray) -> np.ndarray:
    """(N,) sub-step position of each column's minimum: a parabola through its neighbours.
    scores (shifts, N), best (N,) argmin per column."""
    cols = np.arange(scores.shape[1])
    inner = (best > 0) & (best < len(scores) - 1)
    lo = scores[np.clip(best - 1, 0, None), cols]
    mid = scores[best, cols]
    hi = scores[np.clip(best + 1, None, len(scores) - 1), cols]
    curve = lo - 2 * mid + hi
    step = np.where(inner & (curve > 0), 0.5 * (lo - hi) / np.where(curve > 0, curve, 1.0), 0.0)
    return best + np.clip(step, -0.5, 0.5)


def match_many(query: LocalSignature, models: Sequence[LocalSignature], params: LocalParams,
               tolerance: float = TOLERANCE, cap: float = CAP, mutual: bool = False) -> list[PartialMatch]:
    """Score a query against models, all signed with `params` (a model's leading `params.slopes`
    slopes are its signature; the query's are read in windows, one per scale hypothesis). mutual: also
    the mutual share at each model's winning scale (one more hypothesis's product: about a sixth more)."""
    if not models:
        return []
    width = params.slopes
    shifts = min(query.slopes.shape[1] - width + 1, params.shifts)
    if shifts < 1 or any(m.slopes.shape[1] < width for m in models):
        raise ValueError(f"signatures shorter than the grid's {width} slopes")
    kept = [m.valid >= MIN_SLOPES for m in models]
    counts = np.array([int(k.sum()) for k in kept])
    usable = [int(i) for i in np.flatnonzero(counts)]  # a model with no trusted sample matches nothing
    if len(usable) == 0:
        return [PartialMatch(distance=cap, forward=0.0, reverse=0.0, scale=1.0) for _ in models]
    stacked = np.concatenate([models[i].slopes[kept[i], :width] for i in usable])  # (S, J)
    starts = np.concatenate([[0], np.cumsum(counts[usable])[:-1]])
    scores = np.full((shifts, len(usable)), np.inf)
    forwards = np.zeros((shifts, len(usable)))
    for shift in range(shifts):
        qvalid = np.minimum(query.valid.astype(np.int64) - shift, width)
        rows = qvalid >= MIN_SLOPES
        if not rows.any():
            continue
        d = _sq_distances(query.slopes[rows, shift:shift + width], qvalid[rows], stacked)  # (p', S)
        nearest = np.minimum.reduceat(d, starts, axis=1)  # (p', N) per model
        qa = query.area[rows].astype(np.float64)
        qa = qa / qa.sum()
        scores[shift] = qa @ np.minimum(nearest, cap)
        forwards[shift] = qa @ (nearest <= tolerance)
    best = np.argmin(scores, axis=0)
    finite = np.where(np.isfinite(scores), scores, cap)
    scale = params.ratio ** -_refine(finite, best)
    out = [PartialMatch(distance=cap, forward=0.0, reverse=0.0, scale=1.0) for _ in models]
    for c, i in enumerate(usable):
        fwd = float(min(forwards[best[c], c], 1.0))
        out[i] = PartialMatch(distance=float(min(finite[best[c], c], cap)), forward=fwd,
                              reverse=float(min(fwd * scale[c], 1.0)), scale=float(scale[c]),
                              shift=int(best[c]))
    if mutual:
        shares = mutual_shares(query, [models[i] for i in usable], [int(b) for b in best], params)
        for c, i in enumerate(usable):
            out[i] = replace(out[i], mutual=float(shares[c]))
    return out


def region(query: LocalSignature, model: LocalSignature, shift: int, params: LocalParams,
           tolerance: float = TOLERANCE) -> Region | None:
    """The model samples the query's trusted samples match under scale hypothesis `shift` (a
    PartialMatch's), weighted by the query area each stands for; None when the model's signature has no
    sample vertices (saved before they were stored)."""
    return regions(query, [model], [shift], params, tolerance)[0]


def regions(query: LocalSignature, models: Sequence[LocalSignature], shifts: Sequence[int],
            params: LocalParams, tolerance: float = TOLERANCE) -> list[Region | None]:
    """region() of each model at its shift, the models of one shift in one product: the hits of a page
    cost about one scale hypothesis of a match each, a sixth of match_many's six."""
    weights = {i: np.zeros(len(m.slopes)) for i, m in enumerate(models) if m.vertex is not None}
    with_vertex = [i for i in range(len(models)) if i in weights]
    for j, _, qa, cols, d in _at_shift(query, [models[i] for i in with_vertex],
                                        [shifts[i] for i in with_vertex], params):
        nearest = np.argmin(d, axis=1)  # (p',) into cols
        hit = d[np.arange(len(nearest)), nearest] <= tolerance
        np.add.at(weights[with_vertex[j]], cols[nearest[hit]], qa[hit])
    out: list[Region | None] = [None] * len(models)
    for i in with_vertex:
        vertex = models[i].vertex
        assert vertex is not None
        out[i] = Region(vertex=vertex.astype(np.int32), weight=weights[i])
    return out


def _at_shift(query: LocalSignature, models: Sequence[LocalSignature], shifts: Sequence[int],
              params: LocalParams) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Per model with trusted samples on both sides, at its shift: (its index, the trusted query rows,
    their area shares (sum 1), its trusted sample indices, the (rows, samples) squared distances); the
    models of one shift in one product."""
    width = params.slopes
    for shift in sorted(set(shifts)):
        qvalid = np.minimum(query.valid.astype(np.int64) - shift, width)
        rows = np.flatnonzero(qvalid >= MIN_SLOPES)
        group = [i for i, s in enumerate(shifts) if s == shift]
        cols = [np.flatnonzero(models[i].valid >= MIN_SLOPES) for i in group]
        if not len(rows) or query.slopes.shape[1] < shift + width or not sum(map(len, cols)):
            continue
        stacked = np.concatenate([models[i].slopes[c, :width] for i, c in zip(group, cols, strict=True)])
        d = _sq_distances(query.slopes[rows, shift:shift + width], qvalid[rows], stacked)  # (p', S)
        qa = query.area[rows].astype(np.float64)
        qa = qa / qa.sum()
        start = 0
        for i, c in zip(group, cols, strict=True):
            if len(c):
                yield i, rows, qa, c, d[:, start:start + len(c)]
            start += len(c)


def mutual_shares(query: LocalSignature, models: Sequence[LocalSignature], shifts: Sequence[int],
                  params: LocalParams) -> np.ndarray:
    """(len(models),) per model, at its shift, the query's trusted area whose nearest model sample has
    it as its own nearest trusted query sample (at any distance: the capped mean scores how near)."""
    out = np.zeros(len(models))
    for i, _, qa, _, d in _at_shift(query, models, shifts, params):
        ahead = np.argmin(d, axis=1)  # (p',) each query row's nearest model sample
        back = np.argmin(d, axis=0)  # (s',) each model sample's nearest query row
        out[i] = qa[back[ahead] == np.arange(len(ahead))].sum()
    return out
