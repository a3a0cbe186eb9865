"""Where a piece lies on a model: a similarity fit that shows the piece was cut from it (issue 33).

The local signatures rank a piece's candidates by how alike their heat is; they cannot tell the model
a piece was cut from from a class-mate or a look-alike of one limb. Geometry can: a piece of a stored
model, moved, rescaled or mirrored, lies on that model's surface, and on no other.

Per candidate (both signatures must carry their `surface`):
1. pairs: each trusted query sample and its nearest model sample in slopes, at the match's scale
   hypothesis (PartialMatch.shift), the pairs the partial distance already reads;
2. a screen: HYPOTHESES similarities (each triple of pairs fitted as a rotation and as a reflection),
   the triples drawn at random (a fixed seed: the same answer every time) and those whose triangles
   agree taken first (_triples), those whose scale gives the piece a share of the model's area outside
   SHARE refused; the screen's score is the best one's share of pairs that agree within INLIER model
   vertex spacings;
   then a check: CHECK_ROUNDS rounds of ICP of the piece's first CHECK_POINTS samples (a coarser
   farthest-point sample) from those starts, and the share of them that then lies within COVER
   spacings of the model (`checked`). A candidate's promise is its check plus half its inlier share;
3. the fit, for the candidates of most promise (and the best scores): trimmed ICP of the piece's
   samples onto the model's vertices, with scale, from the STARTS best hypotheses (EARLY rounds each,
   then the KEEP that cover most go on);
4. covered: the share of the piece's samples within COVER model vertex spacings of a model vertex.
   A fit with covered >= COVERED (and its share in SHARE) shows the piece lies on the model.
   A piece that lies on none of the models fitted gets a second look: the SECOND most promising are
   screened again with other triples and fitted again.

Coordinates are each surface's at unit area (the describe's), so scale² is the share of the model's
area the piece stands for. Measured on SHREC'11's held-out pieces (docs/partial.md): fitted onto its
source alone, a piece passes for 0.88-0.93 of them (0.68-0.87 before the triangles agreed first); a
model of another class passed in none of about 100,000 offline fits, and twice in 720 served pieces.
Ordered by their inlier share alone, the sources a fit passes on stood past the 32nd candidate for 8 of
107 held-out two-cut pieces and 13 of 102 views; ordered by promise, for 1 and 1 (the check costs about
1 ms a candidate, the screen about 2.5 ms, a fit 12 ms).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from app.core.partial import LocalParams, LocalSignature
from app.core.partial_match import PartialMatch, _at_shift
from app.core.variants.align import Similarity, icp_batch, umeyama_batch

HYPOTHESES = 256  # similarities drawn by the screen, half of them mirrored
INLIER = 3.0  # a pair agrees with a similarity within this many spacings (the even mesh's: spacing())
SHARE = (0.2, 1.25)  # the share of the model's area a piece may stand for (scale²)
STARTS = 8  # the screen's best similarities that ICP starts from
ROUNDS = 20  # ICP rounds at most
EARLY = 5  # ICP rounds every start makes; then the KEEP that cover most make the rest
KEEP = 3
COVER = 1.0  # a piece sample lies on the model within this many model vertex spacings
COVERED = 0.8  # share of the piece's samples that must lie on the model
MIN_PAIRS = 8  # fewer trusted pairs: no screen
DRAWS = 16  # triples drawn per triple kept: those whose triangles agree (_triples) are kept first
TRIANGLE = 1.0  # a triangle agrees when its sides agree within this many INLIER distances
CHECK_POINTS = 64  # the piece's first samples (farthest-point order) a screen's check moves
CHECK_ROUNDS = 2  # ICP rounds of the check
CHECK_INLIERS = 0.5  # the inlier share's weight in a candidate's promise (the check's is 1)
# candidates fitted per piece: those of most promise, and the first by score (SHREC'11's held-out
# pieces: the sources that pass are within these for 0.99 of the pieces, docs/partial.md)
BY_SCREEN = 32
BY_SCORE = 10
# a piece that lies on none of them gives the SECOND most promising a second screen (other triples) and
# fit: a fit fails from wrong starts, and another draw finds right ones for some (docs/partial.md)
SECOND = 8
CHUNK = 32  # candidates screened between two looks at the clock
SECOND_SEED = 1_000_003  # the second screens' seeds: this plus the candidate's index, apart from the first's


@dataclass(frozen=True)
class Screen:
    """A candidate's screen: the share of its pairs that the best similarity agrees with, the STARTS
    best similarities (query sample coordinates -> model coordinates), and the check: the share of the
    piece's first CHECK_POINTS samples within COVER spacings of the model after CHECK_ROUNDS of ICP
    from each of those starts, the best of them."""

    inliers: float
    starts: tuple[Similarity, ...]
    checked: float = 0.0

    @property
    def promise(self) -> float:
        """What orders the candidates to fit: the check, and half the inlier share. Why both: the
        check sees the whole piece against the whole model, the pairs only what the slopes paired; the
        pairs break the check's ties (64 samples: steps of 1/64)."""
        return self.checked + CHECK_INLIERS * self.inliers


@dataclass(frozen=True)
class PieceFit:
    """A piece fitted onto a model: `similarity` takes the piece's coordinates (its surface at unit
    area) to the model's.

    covered   : share of the piece's samples within COVER spacings of the model's vertices, in [0, 1]
    residual  : mean distance of the ICP's kept pairs, in model vertex spacings
    similarity: its scale² is the share of the model's area the piece stands for
    """

    covered: float
    residual: float
    similarity: Similarity

    @property
    def share(self) -> float:
        return self.similarity.scale ** 2

    @property
    def lies_on(self) -> bool:
        """Whether the fit shows the piece lies on the model."""
        return self.covered >= COVERED and SHARE[0] <= self.share <= SHARE[1]


def spacing(n: int) -> float:
    """The mean edge of a triangulation of n vertices spread evenly over unit area: sqrt(2 / (√3 n)),
    the yardstick of the screen (a fit measures the real one)."""
    return float(np.sqrt(2.0 / (np.sqrt(3.0) * max(n, 1))))


def points(signature: LocalSignature) -> np.ndarray | None:
    """(p, 3) the samples' coordinates (None: the signature has no surface or sample vertices)."""
    if signature.surface is None or signature.vertex is None:
        return None
    return signature.surface[signature.vertex].astype(np.float64)


def screens(query: LocalSignature, models: Sequence[LocalSignature], found: Sequence[PartialMatch],
            params: LocalParams, seed: int = 0) -> list[Screen | None]:
    """One screen per model (None: a surface missing, or fewer than MIN_PAIRS trusted pairs), each at
    its match's shift. The models of one shift are paired in one product (partial_match._at_shift)."""
    out: list[Screen | None] = [None] * len(models)
    qpoints = points(query)
    if qpoints is None:
        return out
    usable = [i for i, m in enumerate(models) if m.surface is not None and m.vertex is not None]
    rng = np.random.default_rng(seed)
    mirrored = np.arange(HYPOTHESES) >= HYPOTHESES // 2
    for j, rows, _, cols, d in _at_shift(query, [models[i] for i in usable],
                                        [found[i].shift for i in usable], params):
        if len(rows) < MIN_PAIRS:
            continue
        model = models[usable[j]]
        mpoints = points(model)
        assert mpoints is not None and model.surface is not None
        nearest = np.argmin(d, axis=1)
        src, dst = qpoints[rows], mpoints[cols[nearest]]  # (p', 3) each
        tolerance = INLIER * spacing(len(model.surface))
        pick = _triples(src, dst, rng, tolerance)
        rotation, scale, shift = umeyama_batch(src[pick], dst[pick], mirrored, True)
        allowed = (scale * scale >= SHARE[0]) & (scale * scale <= SHARE[1])
        moved = scale[:, None, None] * src[None] @ rotation.transpose(0, 2, 1) + shift[:, None]  # (h, p', 3)
        agree = (np.linalg.norm(moved - dst[None], axis=2) < tolerance).sum(axis=1)
        agree = np.where(allowed, agree, 0)
        best = np.argsort(-agree, kind="stable")[:STARTS]
        starts = tuple(Similarity(float(scale[b]), rotation[b], shift[b]) for b in best if agree[b] > 0)
        out[usable[j]] = Screen(float(agree[best[0]]) / len(src), starts,
                                _check(qpoints[:CHECK_POINTS], model.surface, starts))
    return out


def _check(sample: np.ndarray, surface: np.ndarray, starts: tuple[Similarity, ...]) -> float:
    """The largest share of sample (c, 3) within COVER spacings (spacing(): the even mesh's) of the
    surface's vertices (v, 3) after CHECK_ROUNDS of ICP from each start (0.0: no start). A short fit:
    a start near the right one has pulled most of the piece onto the model by then."""
    if not starts:
        return 0.0
    target = surface.astype(np.float64)
    tree = cKDTree(target)
    moved, _ = icp_batch(sample, tree, target, list(starts), CHECK_ROUNDS, with_scale=True)
    return max(_covered(tree, sample, f, COVER * spacing(len(target))) for f in moved)


def _covered(tree: cKDTree, points: np.ndarray, similarity: Similarity, near: float) -> float:
    """The share of points (p, 3), moved by the similarity, within `near` of the tree's points."""
    return float((tree.query(similarity.apply(points))[0] < near).mean())


def _triples(src: np.ndarray, dst: np.ndarray, rng: np.random.Generator, tolerance: float) -> np.ndarray:
    """(HYPOTHESES, 3) indices of pairs, three per hypothesis, each triple drawn twice (as a rotation
    and as a reflection) among the pairs src -> dst (p', 3) each. Of DRAWS x HYPOTHESES / 2 triples
    drawn, those whose triangles agree come first: a similarity keeps the ratios of a triangle's sides,
    so a triple of right pairs has model sides within TRIANGLE tolerances of scale x its query sides
    (scale: the ratio of the perimeters), a scale² in SHARE, and, to pin a rotation, model sides longer
    than 2 tolerances. The rest fill up. Where few pairs are right (a piece's slopes near its cut, a
    limb's look-alike) this finds the right triples that drawing 128 at random would miss."""
    half = HYPOTHESES // 2
    tri = rng.integers(0, len(src), size=(half * DRAWS, 3))
    q, m = src[tri], dst[tri]  # (t, 3, 3)
    dq = np.linalg.norm(q - np.roll(q, 1, axis=1), axis=2)  # (t, 3) the sides
    dm = np.linalg.norm(m - np.roll(m, 1, axis=1), axis=2)
    scale = dm.sum(axis=1) / np.maximum(dq.sum(axis=1), 1e-12)
    agree = ((np.abs(dm - scale[:, None] * dq) < TRIANGLE * tolerance).all(axis=1)
             & (dm.min(axis=1) > 2 * tolerance)
             & (scale * scale >= SHARE[0]) & (scale * scale <= SHARE[1]))
    order = np.argsort(~agree, kind="stable")[:half]  # the agreeing triples first, in drawing order
    return np.concatenate([tri[order], tri[order]])


def fit(query: LocalSignature, model: LocalSignature, screen: Screen) -> PieceFit | None:
    """The piece's samples fitted onto the model's vertices by trimmed ICP from the screen's starts,
    the fit that covers most (None: no start, or a surface missing)."""
    qpoints = points(query)
    if qpoints is None or model.surface is None or not screen.starts:
        return None
    target = model.surface.astype(np.float64)
    tree = cKDTree(target)
    gap = float(np.median(tree.query(target, k=2)[0][:, 1]))  # the model's own vertex spacing
    early, _ = icp_batch(qpoints, tree, target, list(screen.starts), EARLY, with_scale=True)
    # the KEEP starts that cover most after EARLY rounds go on: a third of the cost of ROUNDS for all
    covers = np.array([_covered(tree, qpoints, f, COVER * gap) for f in early])
    going = [early[i] for i in np.argsort(-covers, kind="stable")[:KEEP]]
    fits, costs = icp_batch(qpoints, tree, target, going, ROUNDS - EARLY, with_scale=True)
    best: PieceFit | None = None
    for f, cost in zip(fits, costs, strict=True):
        got = PieceFit(covered=_covered(tree, qpoints, f, COVER * gap),
                       residual=float(cost) / gap if gap > 0 else float("inf"), similarity=f)
        if best is None or (got.lies_on, got.covered) > (best.lies_on, best.covered):
            best = got
    return best


def to_fit(screened: Sequence[Screen | None], by_score: Sequence[int]) -> list[int]:
    """Indices of the candidates to fit: the BY_SCREEN of most promise and the first BY_SCORE of
    `by_score` (candidate indices in score order) that have a screen, most promise first."""
    ranked = sorted((j for j, s in enumerate(screened) if s is not None and s.starts),
                    key=lambda j: (-screened[j].promise, j))  # type: ignore[union-attr]
    first = [j for j in by_score if screened[j] is not None and screened[j].starts][:BY_SCORE]  # type: ignore[union-attr]
    return list(dict.fromkeys(ranked[:BY_SCREEN] + first))


@dataclass(frozen=True)
class Fitted:
    """What fitted() did: one fit (None: not fitted) per candidate, and how far it got.

    screened / screen_of: candidates screened, of those with a signature and a score (fewer: the
    deadline stopped the screens); made / chosen: fits made, of the candidates to_fit chose; again:
    second screens and fits (a piece that lay on none)."""

    fits: list[PieceFit | None]
    screened: int = 0
    screen_of: int = 0
    made: int = 0
    chosen: int = 0
    again: int = 0

    @property
    def cut(self) -> bool:
        """Whether the deadline left candidates unscreened or chosen ones unfitted."""
        return self.screened < self.screen_of or self.made < self.chosen


def fitted(query: LocalSignature, models: Sequence[LocalSignature | None],
           found: Sequence[PartialMatch | None], params: LocalParams, deadline: float | None = None,
           always: int = 4) -> Fitted:
    """The fits, one per candidate: models (their signatures, None: unknown) and found (their matches,
    None: unscored) align. The candidates are screened best score first (CHUNK at a time), and those
    to_fit chooses are fitted most promise first; past `deadline` (time.monotonic(); None: none) no
    more screens, and no more fits once the first `always` are made. If the piece lies on none of
    them, the SECOND most promising are screened again with other triples and fitted again (before
    the deadline): a fit that passes replaces the first."""
    out: list[PieceFit | None] = [None] * len(found)
    have = [j for j, (m, s) in enumerate(zip(found, models, strict=True)) if m is not None and s is not None]
    sigs = [models[j] for j in have]
    matches = [found[j] for j in have]
    by_score = sorted(range(len(have)), key=lambda i: (matches[i].score, have[i]))  # type: ignore[union-attr]
    screened: list[Screen | None] = [None] * len(have)
    reached = 0
    for start in range(0, len(by_score), CHUNK):  # best scores first: a deadline cuts the likeliest last
        if start and deadline is not None and time.monotonic() > deadline:
            break
        part = by_score[start:start + CHUNK]
        got = screens(query, [sigs[i] for i in part], [matches[i] for i in part], params,  # type: ignore[misc]
                      seed=start)
        for i, screen in zip(part, got, strict=True):
            screened[i] = screen
        reached += len(part)
    chosen = to_fit(screened, by_score)
    made = 0
    for i in chosen:
        if deadline is not None and made >= always and time.monotonic() > deadline:
            break
        screen, model = screened[i], sigs[i]
        assert screen is not None and model is not None
        out[have[i]] = fit(query, model, screen)
        made += 1
    again = 0
    if not any(f is not None and f.lies_on for f in out):
        for i in chosen[:min(made, SECOND)]:
            if deadline is not None and time.monotonic() > deadline:
                break
            again += 1
            model = sigs[i]
            assert model is not None
            (screen,) = screens(query, [model], [matches[i]], params, seed=SECOND_SEED + i)  # type: ignore[list-item]
            redone = fit(query, model, screen) if screen is not None else None
            if redone is not None and redone.lies_on:
                out[have[i]] = redone
    return Fitted(out, reached, len(have), made, len(chosen), again)


def leading(fits: Sequence[PieceFit | None]) -> list[int]:
    """Indices of the fits that show the piece lies on their model, the most covered first."""
    shown = [j for j, f in enumerate(fits) if f is not None and f.lies_on]
    return sorted(shown, key=lambda j: (-fits[j].covered, j))  # type: ignore[union-attr]
