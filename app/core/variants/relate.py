"""Verify a candidate pair and say how the two meshes are related, with the numbers behind it.

relate(a, b) answers for the query `a` against the stored `b`:

- identical      the same triangles on the same vertices, in place (any format, vertex or face order);
- moved          the same triangles after a rigid motion;
- rescaled       the same triangles after a uniform scale (and perhaps a motion): `scale` says by what;
- mirrored       the same triangles after a reflection (and perhaps a scale and a motion);
- retriangulated the same surface within a tolerance, other triangles (remeshed, decimated, repaired,
                 slightly noisy); `scale` and `mirrored` still say how it sits;
- part_of        every object of `a` is one of the objects of `b` (a part of a plate or kit);
- contains       every object of `b` is one of the objects of `a` (a plate holding `b`, perhaps copies);
- similar        none of the above: only the ranking relates them.

Distances are relative to the bounding-box diagonal of `b`. `transform` (4 x 4) maps `a` onto `b`
(for `contains`, the matched part of `a` onto `b`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from app.core.variants.align import (
    ICP_ITERATIONS,
    Similarity,
    as_they_lie,
    hypotheses,
    icp_batch,
    to_world,
    umeyama,
)
from app.core.variants.anchors import anchored_fits
from app.core.variants.gate import RADIUS, may_relate
from app.core.variants.onesided import LiesOn, cover_margin, side, vertex_subset
from app.core.variants.prepared import Prepared, face_keys

RELATIONS = ("identical", "moved", "rescaled", "mirrored", "retriangulated", "part_of", "contains", "similar")
EXACT = ("identical", "moved", "rescaled", "mirrored")
CHAMFER_MAX = 0.006  # same surface: mean surface distance below 0.6 % of the diagonal ...
HAUSDORFF_MAX = 0.06  # ... and no point farther than 6 % (a punched hole, a decimated corner)
COVER_TOLERANCE = 0.01  # a sample is "covered" by the other surface within 1 % of the diagonal
IDENTITY_TOL = 1e-4  # rotation angle (rad), |log scale| and translation / diagonal read as "none"
COARSE_POINTS = 64  # ICP on a subsample to rank the hypotheses, then more points on the best ...
# ... or on this many when the face counts allow the same triangles: those are looked for from the
# coarse fits near the best, and a renumbered similarity of the held-out sample was missed at 64
COARSE_POINTS_EXACT = 128
FINE_POINTS = 1024
SCREEN_POINTS = 64  # past 2 SCREEN_KEEP hypotheses, a 3-round ICP on this many points screens them ...
SCREEN_KEEP = 2  # ... and the best this many of each handedness go on (the 8 sign choices: 4) ...
SCREEN_KEEP_EXACT = 4  # ... or this many when the face counts allow the same triangles (all 8 kept)
MIRROR_MARGIN = 0.8  # an improper fit wins only when its ICP cost is 20 % lower
REFINE = 2  # hypotheses of each handedness polished on FINE_POINTS when the quick decision is not made
FINE_SETTLE = 5  # ... of which the best of each handedness, after this many rounds ...
SETTLE_POINTS = 256  # ... on this many points (as many as the quick distances), goes on alone on FINE_POINTS
QUICK_POINTS = 256  # the distances measured on this many samples first, under the best fit polished ...
QUICK_FIT_POINTS = 128  # ... on this many points for QUICK_ROUNDS rounds (256 x 8 before: a quarter of the
QUICK_ROUNDS = 4  # work; the closest true variant's quick margin 0.80 / 0.95 / 0.98 of its threshold on
# three samples against 0.75 / 0.95 / 0.98, and every verdict of four samples the same: docs/variants.md)
QUICK_MARGIN = 4.0  # ... and four times past every tolerance there is `similar` without more work
# ... or twice when both meshes have FIRM_VERTICES vertices or more: the quick fit of so many vertices
# is near the best one (true variants found on both benchmark samples with both meshes that large:
# quick margin 1.5 at most, 137 pairs; decimations to ~27 vertices reached 3.1)
QUICK_MARGIN_FIRM = 2.0
FIRM_VERTICES = 30
MIDDLE_POINTS = 512  # after the fine fit, the distances on this many samples first ...
MIDDLE_MARGIN = 2.0  # ... decide `similar` at twice the tolerances (a subsample's largest distance is
# never above the full samples', its means and quantiles are within a few per cent of theirs)
EXACT_ROUNDS = 4
# after the fine fit, the same triangles are looked for from farther and for longer: a near-symmetric
# renumbered copy (a faceted cylinder, a cake) fits its own surface at any turn about the axis, and
# the surface fit may end a fraction of a facet off, 1-3 % of the diagonal at the vertices; vertex ICP
# from there snaps onto the vertices, and the exact test below still decides
FINAL_REACH = 0.1
FINAL_ROUNDS = 12
EXACT_TOL = 1e-4  # same triangles: every vertex within this fraction of the diagonal of its partner
MAX_PARTS = 8  # objects of a multi-object mesh verified one by one ...
PART_RADIUS = RADIUS  # ... against the objects of the other that gate.may_relate lets through, the nearest
PART_TRIES = 2  # this many of them tried before an object is given up
ONE_SIDED_CHAMFER = 0.06  # past this symmetric mean distance the one-sided test is not tried


@dataclass(frozen=True)
class Evidence:
    relation: str
    confidence: float
    chamfer: float  # symmetric mean surface distance / diagonal of b
    hausdorff: float  # symmetric max surface distance / diagonal of b
    forward: float  # fraction of a's surface within 1 % of the diagonal of b's
    reverse: float  # fraction of b's surface within 1 % of the diagonal of a's
    scale: float
    mirrored: bool
    same_triangles: bool
    transform: list[list[float]]
    copies: int = 1  # for part_of / contains: how many matching objects the larger one holds
    # one-sided test (onesided.py), when the symmetric one failed: does one mesh lie on the other?
    lies_on_other: bool | None = None  # True: a lies on b (a is the coarser copy); False: b on a
    resolution: float | None = None  # the lying mesh's mean edge / diagonal of b
    slack: float | None = None  # what its tolerances grow with: that edge times its coarsening
    vertex_gap: float | None = None  # 99 % of its vertices within this of the other surface
    uncovered: float | None = None  # 90 % of the other surface within this of it
    screened: bool = False  # True: ruled out by the invariants (gate.py), no fit made, nothing measured

    def to_dict(self) -> dict:
        return asdict(self)


def relate(a: Prepared, b: Prepared) -> Evidence:
    """The relation of `a` to `b` (module docstring), by whole surfaces first, then by objects."""
    whole = verify(a, b) if may_relate(a, b) else None  # not at all when the invariants rule it out
    if whole is not None and whole.relation != "similar":
        return whole
    na, nb = len(a.parts), len(b.parts)
    found = None  # by objects: a relation, or the `similar` of the object pair that ended the search
    if nb > 1 and nb > na:
        found = _parts_in(a, b)
    elif na > 1 and na > nb:
        found = _parts_in(b, a)
        if found is not None:
            found = _seen_from_other(found, "contains" if found.relation == "part_of" else found.relation)
    if found is not None and found.relation != "similar":
        return found
    return whole or found or UNRELATED


def _seen_from_other(ev: Evidence, relation: str) -> Evidence:
    """The evidence of b's relation to a, as a's relation to b: inverse transform and scale."""
    inverse = np.linalg.inv(np.asarray(ev.transform))
    flipped = None if ev.lies_on_other is None else not ev.lies_on_other
    return replace(ev, relation=relation, forward=ev.reverse, reverse=ev.forward, scale=1.0 / ev.scale,
                   transform=inverse.tolist(), lies_on_other=flipped)


# the answer for a pair that gate.may_relate (and, for objects, _parts_in) rules out before any fit:
# nothing was measured, so the distances are not numbers
UNRELATED = Evidence("similar", 1.0, float("nan"), float("nan"), float("nan"), float("nan"), 1.0, False,
                     False, np.eye(4).tolist(), screened=True)


def verify(a: Prepared, b: Prepared) -> Evidence:
    """Whole surface against whole surface: the exact relations, retriangulated or similar.

    The axis hypotheses are fitted on a few hundred points (screened first on fewer, more of them kept
    when the face counts allow the same triangles); unless the same triangles fit, the best fit is
    polished with scale on those points and the surface distances are measured on QUICK_POINTS
    samples: a pair far from any relation there is decided `similar`. Only the others get the fit
    polished on FINE_POINTS and the distances on the full samples."""
    exact = _exact(a, b, Similarity(1.0, np.eye(3), np.zeros(3)))  # in place: no search needed
    if exact is None and (guess := _same_order_fit(a, b)) is not None:
        exact = _exact(a, b, guess)  # moved or rescaled with the vertex order kept: no search either
    if exact is not None:
        return _exact_evidence(b, *exact)
    fa, fb = a.frame, b.frame
    same_count = _face_counts_match(a, b)
    ranked = _hypotheses(a, b, SCREEN_KEEP_EXACT if same_count else SCREEN_KEEP)
    best_cost = min(r[0] for r in ranked)
    for cost, fit in ranked if same_count else []:  # the same triangles under a fit near the best
        if cost <= 2.0 * best_cost + 1e-3:
            exact = _exact(a, b, to_world(fa, fb, fit))
            if exact is not None:
                return _exact_evidence(b, *exact)
    # the best proper coarse fit, and the best mirrored one only where it competes (see MIRROR_MARGIN),
    # polished with scale on a few hundred points for the quick decision
    proper = next(r for r in ranked if not r[1].mirrored)
    rough = [proper[1]] + [r[1] for r in ranked if r[1].mirrored and r[0] < proper[0]][:1]
    quick_points = a.normalised_samples[:: max(1, len(a.normalised_samples) // QUICK_FIT_POINTS)]
    _, quick_fit = _polished(a, b, quick_points, rough, QUICK_ROUNDS)
    firm = min(a.mesh.n_vertices, b.mesh.n_vertices) >= FIRM_VERTICES
    quick_margin = QUICK_MARGIN_FIRM if firm else QUICK_MARGIN
    quick = _evidence(a, b, quick_fit, points=QUICK_POINTS, decide=quick_margin)
    if quick.relation == "similar" and quick.confidence >= 1.0 - 0.5 / quick_margin:
        return quick  # far from any relation on a subsample (margin >= quick_margin): decided
    # undecided: the best REFINE of each handedness polished on more points, from their turns alone
    # (the centroids already meet at 0)
    rough = [r[1] for r in ranked if not r[1].mirrored][:REFINE]
    rough += [r[1] for r in ranked if r[1].mirrored][:REFINE]
    cost, best, fits = _fine_fit(a, b, rough)
    # the same vertices after all? from each handedness's final fit: a mirrored copy of a nearly
    # mirror-symmetric shape fits its surface about as well either way, and the proper fit wins there
    for fit in fits if same_count else []:
        exact = _exact(a, b, fit, FINAL_REACH, FINAL_ROUNDS)
        if exact is not None:
            return _exact_evidence(b, *exact)
    # under the final fit, a quarter of the samples first: twice past every tolerance there is `similar`
    middle = _evidence(a, b, best, points=MIDDLE_POINTS, decide=MIDDLE_MARGIN)
    if middle.relation == "similar" and middle.confidence >= 1.0 - 0.5 / MIDDLE_MARGIN:
        return middle
    found = _evidence(a, b, best)
    if same_count and found.relation == "retriangulated" and found.lies_on_other is None:
        # the same surface with as many faces: perhaps the same triangles, renumbered, of a
        # symmetric shape the surface fit cannot orient (anchors.py)
        for fit in anchored_fits(a, b):
            exact = _exact(a, b, fit)
            if exact is not None:
                return _exact_evidence(b, *exact)
    return found


def _fine_fit(
    a: Prepared, b: Prepared, rough: list[Similarity]
) -> tuple[float, Similarity, list[Similarity]]:
    """_polished() on FINE_POINTS of a's samples from the turns of the rough fits (the centroids
    already meet at 0); of more than 2 of them, only the best of each handedness after FINE_SETTLE
    rounds on SETTLE_POINTS goes on (the three samples' verdicts unchanged: docs/variants.md). Also
    the best final fit of each handedness, the chosen one first."""
    fine = a.normalised_samples[:: max(1, len(a.normalised_samples) // FINE_POINTS)]
    starts, rounds = [Similarity(1.0, r.rotation, np.zeros(3)) for r in rough], ICP_ITERATIONS
    if len(starts) > 2:
        settle = a.normalised_samples[:: max(1, len(a.normalised_samples) // SETTLE_POINTS)]
        fits, costs = icp_batch(settle, b.normalised_tree, b.normalised_samples, starts, FINE_SETTLE,
                                with_scale=True)
        ranked = sorted(zip(costs.tolist(), fits, strict=True), key=lambda f: f[0])
        starts = [next(f for _, f in ranked if f.mirrored == m) for m in (False, True)
                  if any(f.mirrored == m for f in fits)]
        rounds -= FINE_SETTLE
    refined = _polished_all(a, b, fine, starts, rounds)
    cost, best = _choose(refined)
    others = [min((r for r in refined if r[1].mirrored == m), key=lambda r: r[0])[1]
              for m in (False, True) if any(r[1].mirrored == m for r in refined)]
    return cost, best, [best] + [f for f in others if f is not best]


def _same_order_fit(a: Prepared, b: Prepared) -> Similarity | None:
    """When a and b have the same triangles on the same vertex numbers (a copy moved or rescaled by a
    program that kept the order), the proper similarity fitted on vertex i -> vertex i; else None.
    The principal axes cannot find that motion for a shape with two equal moments and a near
    symmetry about the third axis (a ring of holes: ICP settles a hole away). A mirrored copy is
    left to the hypotheses, which try every proper motion first (see `mirrored` in the docstring)."""
    fa, fb = a.mesh.faces, b.mesh.faces
    if a.mesh.n_vertices != b.mesh.n_vertices or fa.shape != fb.shape:
        return None
    if not np.array_equal(np.sort(fa, axis=1), np.sort(fb, axis=1)):
        return None
    return umeyama(a.mesh.vertices, b.mesh.vertices, mirrored=False)


def _face_counts_match(a: Prepared, b: Prepared) -> bool:
    """Whether a and b may have the same triangles (a format's rounding may join a few vertices)."""
    return 0.98 * b.mesh.n_faces <= a.mesh.n_faces <= 1.02 * b.mesh.n_faces + 2


def _polished(
    a: Prepared, b: Prepared, points: np.ndarray, rough: list[Similarity], rounds: int = ICP_ITERATIONS
) -> tuple[float, Similarity]:
    """ICP with scale of `points` (a's, normalised) from each rough fit; the best as (cost, similarity
    between the meshes' own coordinates), a mirrored one only when clearly better (MIRROR_MARGIN)."""
    return _choose(_polished_all(a, b, points, rough, rounds))


def _polished_all(
    a: Prepared, b: Prepared, points: np.ndarray, rough: list[Similarity], rounds: int
) -> list[tuple[float, Similarity]]:
    """(cost, similarity between the meshes' own coordinates) of ICP with scale from each rough fit."""
    fits, costs = icp_batch(points, b.normalised_tree, b.normalised_samples, rough, rounds, with_scale=True)
    return list(zip(costs.tolist(), [to_world(a.frame, b.frame, f) for f in fits], strict=True))


def _choose(refined: list[tuple[float, Similarity]]) -> tuple[float, Similarity]:
    """The best proper fit, or the best mirrored one when clearly better (MIRROR_MARGIN)."""
    proper = min((r for r in refined if not r[1].mirrored), key=lambda r: r[0], default=None)
    improper = min((r for r in refined if r[1].mirrored), key=lambda r: r[0], default=None)
    if proper is None or (improper is not None and improper[0] < MIRROR_MARGIN * proper[0]):
        assert improper is not None
        return improper  # a (nearly) mirror-symmetric shape fits both ways: mirrored only when clearly
    return proper


def _hypotheses(a: Prepared, b: Prepared, keep: int) -> list[tuple[float, Similarity]]:
    """(ICP cost, fit in normalised coordinates) for each axis hypothesis, proper ones first, each
    handedness by cost. More than 2 `keep` hypotheses are screened on a few points first, and only
    the best `keep` of each handedness go on, and the meshes as they lie (align.as_they_lie) beside
    them: on few points a start as they lie can look better than the axes' right one and displace
    it, so it never competes for those places."""
    axes = [Similarity(1.0, r, np.zeros(3)) for r in hypotheses(a.frame, b.frame)]
    starts = [*axes, Similarity(1.0, as_they_lie(a.frame, b.frame), np.zeros(3))]
    pts = a.normalised_samples
    if len(axes) > 2 * keep:
        screen = pts[:: max(1, len(pts) // SCREEN_POINTS)]
        fits, costs = icp_batch(screen, b.normalised_tree, b.normalised_samples, starts, iterations=3)
        order = np.argsort(costs[: len(axes)])  # the as-they-lie start (last) goes on whatever its cost
        starts = [fits[i] for i in order if not fits[i].mirrored][:keep] + [
            fits[i] for i in order if fits[i].mirrored][:keep] + [fits[-1]]
    coarse = pts[:: max(1, len(pts) // (COARSE_POINTS_EXACT if keep >= SCREEN_KEEP_EXACT else COARSE_POINTS))]
    fits, costs = icp_batch(coarse, b.normalised_tree, b.normalised_samples, starts, iterations=10)
    ranked = list(zip(costs.tolist(), fits, strict=True))
    ranked.sort(key=lambda r: (r[1].mirrored, r[0]))  # proper first: a symmetric shape is not "mirrored"
    return ranked


def _exact(
    a: Prepared, b: Prepared, guess: Similarity, reach: float = 0.02, rounds: int = EXACT_ROUNDS
) -> tuple[Similarity, float] | None:
    """The similarity fitted on vertex correspondences, and its largest vertex residual, if a's
    triangles are b's triangles under it: every vertex of a within EXACT_TOL of a vertex of b,
    and a's triangles, through that vertex map, exactly b's set of triangles. The map may join two of
    a's vertices that a file format's rounding made one (a weld), never two distinct ones. The vertex
    ICP starts only when every vertex under `guess` is within `reach` (of the diagonal) of one of b's
    and runs at most `rounds` rounds."""
    if not _face_counts_match(a, b):
        return None
    va, vb = a.mesh.vertices, b.mesh.vertices
    fit = guess
    probe = va[:: max(1, len(va) // 256)]  # every vertex must be near: a few far ones end it cheaply
    if b.vertex_tree.query(fit.apply(probe), workers=1)[0].max() > reach * b.diagonal:
        return None
    # float32 files round each coordinate to 2^-24 of its magnitude, text files to a number of decimals
    # (6 in many exporters: 5e-7 absolute, 5e-5 of a 1 cm part in metres); 1e-4 of the size covers both
    previous = np.inf
    for _ in range(rounds):  # vertex ICP: from a close guess, the map is right after a round or two
        dist, idx = b.vertex_tree.query(fit.apply(va), workers=1)
        if dist.max() > reach * b.diagonal:
            return None
        fit = umeyama(va, vb[idx], mirrored=guess.mirrored)
        residual = float(np.linalg.norm(fit.apply(va) - vb[idx], axis=1).max())
        extent = np.abs(vb).max() + fit.scale * np.abs(va).max()
        if residual <= EXACT_TOL * b.diagonal + 2.0**-22 * extent:
            break
        if residual >= 0.99 * previous:
            return None  # settled above the tolerance (a noisy copy): more rounds change nothing
        previous = residual
    else:
        return None
    # b's own vertices closer than the tolerance count as one (a format's rounding joins them)
    weld = b.weld(EXACT_TOL * b.diagonal + 2.0**-22 * extent)  # (n_b,) label
    if not np.array_equal(_triangles(weld[idx[a.mesh.faces]]), _triangles(weld[b.mesh.faces])):
        return None
    return fit, residual


def _triangles(faces: np.ndarray) -> np.ndarray:
    """Distinct triangles as vertex sets, (f', ) int64 keys; a row a weld made degenerate left out."""
    s = np.sort(faces, axis=1)
    s = s[(s[:, 0] != s[:, 1]) & (s[:, 1] != s[:, 2])]
    return np.unique(face_keys(s, int(faces.max(initial=0)) + 1))


def _exact_evidence(b: Prepared, sim: Similarity, residual: float) -> Evidence:
    """Same triangles: each point of a triangle moves by a blend of its corners' residuals, so the
    largest vertex residual bounds the Hausdorff distance (and the Chamfer distance) exactly."""
    bound = residual / b.diagonal
    return Evidence(_exact_relation(sim, b.diagonal), 1.0, bound, bound, 1.0, 1.0, sim.scale, sim.mirrored,
                    True, sim.matrix().tolist())


def _evidence(
    a: Prepared, b: Prepared, sim: Similarity, one_sided: bool = True, points: int | None = None,
    decide: float | None = None,
) -> Evidence:
    """The surface distances under `sim` (a's and b's samples, or the first `points` of them: the
    samples are drawn independently, so a prefix is a random subsample), and the one-sided test.
    `decide`: the margin at which the caller calls the pair `similar` from this evidence (and otherwise
    uses it for nothing); the one-sided test is skipped when the symmetric margin is under it, and a
    direction whose coverage alone is that far past its tolerance is not measured (its margin can only
    be larger) and that bound stands for it: the decision is the one the full test would give, the
    margin said may differ from the full test's where it decides nothing or the pair is `similar`."""
    diag = b.diagonal
    ab = b.distance_to(sim.apply(a.samples[0][:points]))  # (N,) a's samples to b's surface
    ba = a.distance_to(_inverse(sim).apply(b.samples[0][:points])) * sim.scale  # (N,) b's to a's, b's units
    chamfer = 0.5 * float(ab.mean() + ba.mean()) / diag
    hausdorff = float(max(ab.max(), ba.max())) / diag
    forward = float((ab <= COVER_TOLERANCE * diag).mean())
    reverse = float((ba <= COVER_TOLERANCE * diag).mean())
    margin = max(chamfer / CHAMFER_MAX, hausdorff / HAUSDORFF_MAX)
    extra: dict = {}
    a_edge, b_edge = a.mean_edge * sim.scale / diag, b.mean_edge / diag
    # a coarser copy on the finer surface? (not asked when the symmetric margin is already under the
    # caller's `decide`: the pair goes on to more work whatever the one-sided test says)
    if one_sided and max(1.0, decide or 1.0) <= margin and chamfer < ONE_SIDED_CHAMFER:
        # "a lies on b" (a's vertices to b, b's samples covered by a), then "b lies on a"
        bounds = (cover_margin(ba / diag, a_edge, b_edge), cover_margin(ab / diag, b_edge, a_edge))
        skipped = [m for m in bounds if decide is not None and m >= decide]  # their margins are >= these
        sides: list[LiesOn] = []
        if decide is None or bounds[0] < decide:
            gaps = b.distance_to(sim.apply(vertex_subset(a.mesh, points, a.used_vertices))) / diag
            sides.append(LiesOn(True, *side(gaps, ba / diag, a_edge, b_edge)))
        if decide is None or bounds[1] < decide:
            back = _inverse(sim).apply(vertex_subset(b.mesh, points, b.used_vertices))
            gaps = a.distance_to(back) * sim.scale / diag
            sides.append(LiesOn(False, *side(gaps, ab / diag, b_edge, a_edge)))
        if sides:
            on = min(sides, key=lambda o: o.margin)  # the better direction ("a lies on b" on a tie)
            extra = {"lies_on_other": on.a_on_b, "resolution": on.resolution, "slack": on.slack,
                     "vertex_gap": on.vertex_gap, "uncovered": on.uncovered}
            margin = min(margin, on.margin)
        margin = min([margin, *skipped])
    if margin < 1.0:
        relation, confidence = "retriangulated", 1.0 - 0.5 * margin
    else:
        relation, confidence = "similar", 1.0 - 0.5 / margin
    return Evidence(relation, round(confidence, 4), chamfer, hausdorff, forward, reverse, sim.scale,
                    sim.mirrored, False, sim.matrix().tolist(), **extra)


def _exact_relation(sim: Similarity, diagonal: float) -> str:
    if sim.mirrored:
        return "mirrored"
    if abs(np.log(sim.scale)) > IDENTITY_TOL:
        return "rescaled"
    angle = np.arccos(np.clip((np.trace(sim.rotation) - 1.0) / 2.0, -1.0, 1.0))
    if angle > IDENTITY_TOL or np.linalg.norm(sim.translation) > IDENTITY_TOL * diagonal:
        return "moved"
    return "identical"


def _inverse(sim: Similarity) -> Similarity:
    rotation = sim.rotation.T
    return Similarity(1.0 / sim.scale, rotation, -rotation @ sim.translation / sim.scale)


def _parts_in(small: Prepared, big: Prepared) -> Evidence | None:
    """Every object of `small` matched to an object of `big` (whole-surface relation other than
    similar); the evidence of the largest object's match, with the copies of it that `big` holds.
    Otherwise the `similar` of the first object pair verified for an object that has no match, or
    None when the fingerprints and the gate rule every pair out (nothing verified)."""
    parts = small.parts[:MAX_PARTS]
    gaps = np.linalg.norm(np.array([p.fingerprint for p in parts])[:, None]
                          - np.array([o.fingerprint for o in big.parts])[None], axis=2)  # (parts, objects)
    # the gate's test per object pair (resolutions are computed only for pairs within the radius)
    gaps = np.where([[g <= PART_RADIUS and may_relate(p, o) for g, o in zip(row, big.parts, strict=True)]
                     for row, p in zip(gaps, parts, strict=True)], gaps, np.inf)
    if not np.isfinite(gaps).any(axis=1).all():
        return None  # an object with no object of `big` it may be related to: nothing to verify
    found: dict[int, list[Evidence]] = {}
    for i in np.argsort(-gaps.min(axis=1)):  # the object least likely to match first: a miss ends it
        row = gaps[i]
        order = [j for j in np.argsort(row) if np.isfinite(row[j])]  # the others: no relation is possible
        matches: list[Evidence] = []
        miss: Evidence | None = None
        for n, j in enumerate(order[: 2 * MAX_PARTS]):
            if not matches and n >= PART_TRIES:
                break  # its nearest objects are not it: a farther one will not be either
            ev = verify(parts[i], big.parts[int(j)])
            if ev.relation != "similar":
                matches.append(ev)
            elif matches:
                break  # candidates come nearest first: the copies are together at the front
            else:
                miss = miss or ev
        if not matches:
            return miss  # `similar`: the first object pair verified for the object that has no match
        found[int(i)] = matches
    matches = found[0]  # the evidence of the largest object (objects come largest first)
    first = Evidence(**{**matches[0].to_dict(), "copies": len(matches)})
    # coverage against the whole of `big`, as the whole-surface check measures it
    placed = Similarity(first.scale, np.asarray(first.transform)[:3, :3] / first.scale,
                        np.asarray(first.transform)[:3, 3])
    whole = _evidence(small, big, placed, one_sided=False)
    return replace(first, relation="part_of", forward=whole.forward, reverse=whole.reverse)
