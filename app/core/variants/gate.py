"""The cheap stage before any alignment: whether two meshes can be related at all, from numbers each
prepared mesh already has (its fingerprint and its resolution), in microseconds.

A fingerprint is area-weighted, so a copy at about the same resolution (the same triangles anywhere,
a remesh, slight noise, a hole, a moderate decimation) moves it little: of the true variants found on
both samples of the detection benchmark (benchmarks/variants_detect.py) whose resolutions are within
COARSE_RATIO of each other, the farthest is 0.426 apart (a remesh of trimesh__pyramids.3mf; then 0.35,
vertex noise roughening a fine surface's area), against SAME_RADIUS = 0.5 (margin 1.17). Only a much
coarser copy moves it farther: the decimations to 10 % found reach 0.89, within RADIUS = 1.0 (the
lookup's radius), with edges 3.15 times as long as the original's or more, against COARSE_RATIO = 2
(margin 1.6). Such a pair can only pass the one-sided test (onesided.py: the coarser mesh lying on
the finer one), which never passes a mesh of fewer than MIN_VERTICES vertices.

The L2 radius lets a pair through on its distance alone, however that distance is spread; a true
variant moves each entry of the fingerprint by a typical amount (the moments' ratios more than the
low D2 quantiles, which barely move). So each entry must also be within its own bound, SAME_BOX for
a pair at about one resolution and COARSE_BOX for a much coarser copy: 1.25 times the largest gap
of that entry over every pair found related (any relation) on both samples of the detection
benchmark (779 pairs within COARSE_RATIO, 92 coarser), rounded up to 0.01 (COARSE_BOX no tighter
than SAME_BOX). Of the 310 pairs verified over 58 realworld ingests before the boxes
(`benchmarks.variants_ingest --limit 60 --max-vertices 60000`: 3 found related, 307 `similar`), the
boxes rule out 221 before any fit and keep the 3; both benchmark samples give the same verdicts.

Entries 7-16 are quantiles of surface samples drawn in face order, so the same surface with its faces
in another order (a repair tool, an exporter, a renumbering) moves them by sampling noise alone; the
boxes above, taken from pairs most of which kept the face order, were narrower than that noise on
six entries of SAME_BOX and one of COARSE_BOX (the D2 10 % quantile: 0.03 in both, where two samplings
of one surface differ by up to 0.046).
So each entry's bound is at least NOISE_FLOOR, 1.25 times the largest gap between two samplings of
one surface (`python -m benchmarks.variants_noise --draws 20`: 116 meshes none of the benchmark's
bases, 2,320 re-orderings), rounded up to 0.01. And since entries 0-6 are exact integrals of the
triangles, which no order changes, a pair whose entries 0-6 agree to rounding (EXACT_MATCH) may have
the same triangles: it is verified whatever its sampled entries say, within SAME_RADIUS of them (the
noise reaches 0.13). Entry 3 is left
out of that test: it is the signed volume, which a repair tool that makes the winding coherent
changes while the triangles stay the same (a realworld mesh with some faces flipped: 0.39 apart on
that entry alone, identical).
"""

from __future__ import annotations

import numpy as np

from app.core.variants.onesided import MIN_VERTICES
from app.core.variants.prepared import Prepared

RADIUS = 1.0  # fingerprint distance past which no relation is verified (a decimation to 10 %: 0.89)
SAME_RADIUS = 0.5  # ... past which only a much coarser copy is (same-resolution variants: 0.426 at most)
COARSE_RATIO = 2.0  # "much coarser": mean edge (over the RMS radius) this many times the other's
# per-entry bounds on |fingerprint a - fingerprint b| (module docstring; entries as fingerprint.py)
# the two samples' true variants (module docstring) ...
_SAME_SEEN = np.array([0.20, 0.12, 0.52, 0.17, 0.27, 0.27, 0.20, 0.08, 0.07, 0.09, 0.08, 0.11, 0.03, 0.05,
                       0.05, 0.06, 0.10])
_COARSE_SEEN = np.array([0.29, 0.36, 0.83, 0.24, 0.33, 0.95, 0.43, 0.18, 0.15, 0.12, 0.20, 0.21, 0.03, 0.06,
                         0.08, 0.10, 0.10])
# ... and no narrower than the sampling noise of the sampled entries 7-16 (the exact ones do not move)
NOISE_FLOOR = np.array([0.0] * 7 + [0.06, 0.07, 0.06, 0.13, 0.14, 0.06, 0.06, 0.07, 0.10, 0.10])
SAME_BOX = np.maximum(_SAME_SEEN, NOISE_FLOOR)
COARSE_BOX = np.maximum(_COARSE_SEEN, NOISE_FLOOR)
EXACT_ENTRIES = 7  # entries 0-6: exact triangle integrals (moments, volume, third moments) ...
WINDING_FREE = np.array([0, 1, 2, 4, 5, 6])  # ... of which all but the volume are free of the winding
# the same triangles give them to rounding: float32 coordinates move an O(1) ratio of moments by about
# 1e-6 of the coordinates' magnitude over the size, so 1e-3 leaves room for a model far off its origin
EXACT_MATCH = 1e-3


def coarsening(a: Prepared, b: Prepared) -> float:
    """How many times longer the coarser mesh's edges are, each relative to its own RMS radius (>= 1)."""
    ra, rb = a.resolution, b.resolution
    return max(ra, rb) / max(min(ra, rb), 1e-300)


def may_relate(a: Prepared, b: Prepared) -> bool:
    """False when no relation but `similar` is possible between the two surfaces (module docstring)."""
    diff = np.abs(a.fingerprint - b.fingerprint)  # (17,)
    if _may_be_same(diff):
        return True  # the same triangles are possible: only sampling noise (and the winding) differ
    gap = float(np.linalg.norm(diff))
    if gap > RADIUS:
        return False
    much_coarser = coarsening(a, b) >= COARSE_RATIO
    if not np.all(diff <= (COARSE_BOX if much_coarser else SAME_BOX)):
        return False
    if gap <= SAME_RADIUS:
        return True
    # only the one-sided test (onesided.py) can pass a far pair, with the coarser mesh lying on the
    # finer one: it needs that mesh much coarser, and never passes one of fewer than MIN_VERTICES
    coarser = a if a.resolution >= b.resolution else b
    return much_coarser and coarser.mesh.n_vertices >= MIN_VERTICES


def _may_be_same(diff: np.ndarray) -> np.ndarray:
    """Whether fingerprint gaps (..., 17) allow the same triangles in any order and winding: the exact
    entries but the volume agree (to EXACT_MATCH), and the sampled ones are within SAME_RADIUS
    (sampling noise: 0.13 at most over 2,320 re-orderings, benchmarks.variants_noise)."""
    exact = np.all(diff[..., WINDING_FREE] <= EXACT_MATCH, axis=-1)
    return exact & (np.linalg.norm(diff[..., EXACT_ENTRIES:], axis=-1) <= SAME_RADIUS)


def may_relate_any(queries: np.ndarray, rows: np.ndarray) -> bool:
    """Whether any fingerprint of one model (queries (q, 17): its whole and objects) and any of another
    (rows (r, 17)) are within RADIUS and COARSE_BOX of each other, or may have the same triangles
    (_may_be_same). When none are, may_relate rules out the whole surfaces and every object pair
    whatever the resolutions (COARSE_BOX is the wider box), so relate() can only answer the gate's
    `similar`: the service then skips reading the stored mesh."""
    diff = np.abs(np.asarray(queries, np.float32)[:, None] - np.asarray(rows, np.float32)[None])  # (q, r, 17)
    near = (np.linalg.norm(diff, axis=2) <= RADIUS) & np.all(diff <= COARSE_BOX, axis=2)
    return bool((near | _may_be_same(diff)).any())
