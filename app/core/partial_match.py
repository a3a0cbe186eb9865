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
The score ranks candidates: the distance less VOTE x CAP x the vote share, the query's trusted area
(at the winning scale) for which the model is among the VOTE_TOP nearest of all the candidates scored,
sample by sample (votes(): it compares the candidates with each other, so it is set after match_many,
over the candidates of one query). Near everywhere is not enough: a source is the best look-alike of
many of the query's samples, a class whose limbs resemble everything's is not. MUTUAL x CAP x the
mutual share (the query's trusted area whose nearest model sample has it as its own nearest query sample)
was served before the vote; measured on all 30 SHREC'11 classes, the vote alone does better (weight 0:
docs/partial.md). That own score is then averaged with the PEERS candidates nearest to the model in the
global index's space (app.core.piece_rank.with_peers): a piece's source class is a group of models that
all cover it, while a look-alike of one limb is usually alone among its neighbours; only candidates
within PEER_RADIUS are peers, so a model with no class-mates keeps its own score.
A pair of samples is compared by their slopes' mean squared difference plus LEVEL x the squared
difference of their heat levels (LocalSignature.level, the query's read at the window's first time:
level_at). The forward share and the region read the slopes alone, so the tolerance keeps its meaning.
Forward and reverse are what a user reads, and `region` where: the share
of the query's area each model sample matches under the winning scale (what the page's 3D view colours).
`head` keeps a signature's first samples: a coarser farthest-point sample of the same shape, for a cheap
first pass over many models.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from app.core.partial import LocalParams, LocalSignature

if TYPE_CHECKING:  # piece_fit reads this module: the type alone, no import cycle at run time
    from app.core.piece_fit import PieceFit

MIN_SLOPES = 4  # a sample with fewer trusted slopes than this sits on the rim: it is not compared
TOLERANCE = 2e-3  # mean squared slope difference under which two samples match
CAP = 4 * TOLERANCE  # one unmatched sample costs at most this: a missing part does not swamp the rest
MUTUAL = 0.0  # weight of the mutual share in the score, in CAPs (1.0 before the vote: docs/partial.md)
VOTE = 0.5  # weight of the vote share in the score, in CAPs (picked on SHREC'11's picking split)
VOTE_TOP = 10  # a query sample votes for the candidates among its this many nearest
# a candidate's score is averaged with its PEERS nearest fellow candidates' (by stored fused L1), this
# much of it theirs (app.core.piece_rank.with_peers; picked on SHREC'11's picking split, docs/partial.md)
PEERS = 5
PEER_WEIGHT = 0.5
# only candidates this near (L1 between stored fused vectors, the shipped vocabulary's space) are peers:
# a SHREC'11 model's 5th nearest class-mate is within 0.94 for 99 % of them, a unique realworld model's
# nearest other model is 1.74 away at the median (docs/partial.md)
PEER_RADIUS = 1.0
# a candidate this near the query (its partial distance) is a stored copy of it (the same upload, a
# re-export): it says nothing about which class the piece is from, so it is nobody's peer (a SHREC'11
# piece's distance to its own whole is 2.9e-4 at the least of 60 measured, docs/partial.md)
COPY_DISTANCE = 5e-3 * TOLERANCE
# weight of the squared difference of two samples' levels (LocalSignature.level, at the window's first
# time) added to their slopes' mean squared difference: the slopes say how fast heat leaves a point, the
# level how much is there, which tells a spider's leg from an octopus's arm (docs/partial.md)
LEVEL = 0.03


@dataclass(frozen=True)
class PartialMatch:
    distance: float  # area-weighted mean over query samples of min(nearest squared distance, CAP)
    forward: float  # in [0, 1]
    reverse: float  # in [0, 1]
    scale: float  # kept share the winning scale implies (1: the query is as large as the model)
    shift: int = 0  # the winning scale hypothesis (the query grid's window), which `region` reads
    mutual: float = 0.0  # the query's trusted area matched one-to-one at that scale (match_many(mutual=True))
    vote: float = 0.0  # the query's trusted area that ranks this model among its VOTE_TOP nearest (votes())
    # the mean `own` score of this model's PEERS nearest fellow candidates (piece_rank.with_peers); NaN:
    # not set (no other candidate, or its stored vector unknown), the score is then its own
    peers: float = float("nan")
    # (p,) each query sample's nearest squared distance at that scale (inf: not trusted there), which
    # votes() compares across candidates; None for a model with no trusted sample
    nearest: np.ndarray | None = field(default=None, repr=False, compare=False)
    # the fit of the piece onto this model (app.core.piece_fit.PieceFit), set by the ranking for the
    # candidates it fitted; None: not fitted
    fit: PieceFit | None = field(default=None, repr=False, compare=False)

    @property
    def own(self) -> float:
        """This match's own score, lower first: the distance less the mutual and vote shares' weights."""
        return self.distance - MUTUAL * CAP * self.mutual - VOTE * CAP * self.vote

    @property
    def score(self) -> float:
        """What a re-ranking orders by, lower first: the own score, averaged with its peers' when set."""
        if math.isnan(self.peers):  # not set: no peers
            return self.own
        return (1.0 - PEER_WEIGHT) * self.own + PEER_WEIGHT * self.peers


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
    level = None if signature.level is None else signature.level[:count]
    return LocalSignature(slopes=signature.slopes[:count], area=signature.area[:count],
                          valid=signature.valid[:count], rim=signature.rim, vertex=vertex, level=level,
                          surface=signature.surface)


def level_at(query: LocalSignature, shift: int, params: LocalParams) -> np.ndarray | None:
    """(p,) each query sample's level at the first time of window `shift` (the one a model's grid
    starts at under that scale hypothesis): its level plus the cumulated (slope + 1)·log(ratio), since
    d log(t·K_t) / d log t = slope + 1. None when the query has no level."""
    if query.level is None:
        return None
    rise = (query.slopes[:, :shift].astype(np.float64) + 1.0).sum(axis=1) * math.log(params.ratio)
    return query.level.astype(np.float64) + rise


def _levels(models: Sequence[LocalSignature], rows: Sequence[np.ndarray]) -> np.ndarray:
    """(S,) the levels of the models' samples `rows`, stacked; NaN for a model without levels."""
    return np.concatenate([m.level[r].astype(np.float64) if m.level is not None else np.full(len(r), np.nan)
                           for m, r in zip(models, rows, strict=True)])


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


def _add_levels(d: np.ndarray, qlevel: np.ndarray, mlevel: np.ndarray, weight: float) -> None:
    """d (p, s) += weight x (qlevel (p,) - mlevel (s,))², in place; nothing where mlevel is NaN (a
    model described before levels were stored is compared on its slopes alone)."""
    gap = np.subtract.outer(qlevel, mlevel)
    np.square(gap, out=gap)
    gap[np.isnan(gap)] = 0.0
    gap *= weight
    d += gap


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
    levels = _levels([models[i] for i in usable], [kept[i] for i in usable])  # (S,)
    starts = np.concatenate([[0], np.cumsum(counts[usable])[:-1]])
    scores = np.full((shifts, len(usable)), np.inf)
    forwards = np.zeros((shifts, len(usable)))
    near = np.full((shifts, len(query.slopes), len(usable)), np.inf)  # per sample, per model
    for shift in range(shifts):
        qvalid = np.minimum(query.valid.astype(np.int64) - shift, width)
        rows = qvalid >= MIN_SLOPES
        if not rows.any():
            continue
        d = _sq_distances(query.slopes[rows, shift:shift + width], qvalid[rows], stacked)  # (p', S)
        qa = query.area[rows].astype(np.float64)
        qa = qa / qa.sum()
        # the forward share reads the slopes alone (the tolerance's meaning); the level only ranks
        forwards[shift] = qa @ (np.minimum.reduceat(d, starts, axis=1) <= tolerance)
        qlevel = level_at(query, shift, params)
        if LEVEL > 0 and qlevel is not None:
            _add_levels(d, qlevel[rows], levels, LEVEL)
        nearest = np.minimum.reduceat(d, starts, axis=1)  # (p', N) per model
        near[shift, rows] = nearest
        scores[shift] = qa @ np.minimum(nearest, cap)
    best = np.argmin(scores, axis=0)
    finite = np.where(np.isfinite(scores), scores, cap)
    scale = params.ratio ** -_refine(finite, best)
    out = [PartialMatch(distance=cap, forward=0.0, reverse=0.0, scale=1.0) for _ in models]
    for c, i in enumerate(usable):
        fwd = float(min(forwards[best[c], c], 1.0))
        out[i] = PartialMatch(distance=float(min(finite[best[c], c], cap)), forward=fwd,
                              reverse=float(min(fwd * scale[c], 1.0)), scale=float(scale[c]),
                              shift=int(best[c]), nearest=near[best[c], :, c].copy())
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


def trusted_area(query: LocalSignature, shift: int, params: LocalParams) -> np.ndarray:
    """(p,) the area share of each query sample trusted under scale hypothesis `shift` (0 elsewhere;
    the trusted ones sum to 1, as a match weighs them)."""
    qvalid = np.minimum(query.valid.astype(np.int64) - shift, params.slopes)
    area = np.where(qvalid >= MIN_SLOPES, query.area.astype(np.float64), 0.0)
    total = area.sum()
    return area / total if total > 0 else area


def votes(query: LocalSignature, found: Sequence[PartialMatch], params: LocalParams,
          top: int = VOTE_TOP) -> np.ndarray:
    """(len(found),) per match, the query's trusted area (at its winning scale) for which its model is
    among the `top` nearest of all the matches' models, sample by sample: a model that is the best
    look-alike of many of the query's samples, not merely near them all, as a source is (and a
    class that shares parts with many, such as limbs, is not). Matches without `nearest` get 0."""
    if not found:
        return np.zeros(0)
    p = len(query.slopes)
    d = np.stack([m.nearest if m.nearest is not None else np.full(p, np.inf) for m in found], axis=1)
    rank = np.argsort(np.argsort(d, axis=1, kind="stable"), axis=1)  # (p, N) rank of each model per sample
    good = (rank < top) & np.isfinite(d)
    by_shift = {shift: trusted_area(query, shift, params) for shift in {m.shift for m in found}}
    area = np.stack([by_shift[m.shift] for m in found], axis=1)  # (p, N)
    return (area * good).sum(axis=0)
