"""The cheap stage before any alignment: whether two meshes can be related at all, from numbers each
prepared mesh already has (its fingerprint and its resolution), in microseconds.

A fingerprint is area-weighted, so a copy at about the same resolution (the same triangles anywhere,
a remesh, slight noise, a hole, a moderate decimation) moves it little: on the detection benchmark's
true variants whose mean edges are within COARSE_RATIO of each other (benchmarks/variants_detect.py,
both samples), the farthest is at 0.35 (0.31 of it in the area term: noise roughens a fine surface),
against SAME_RADIUS = 0.5. Only a much coarser copy (a decimation to 10 % has edges about 3 times as
long) moves it farther, up to about 0.5 on the benchmark, within RADIUS = 1.0 (the lookup's radius).
So a pair farther than SAME_RADIUS is verified only when one mesh is at least COARSE_RATIO times
coarser than the other (the true decimations to 10 % that are found are 3.0 or more).
"""

from __future__ import annotations

import numpy as np

from app.core.variants.onesided import MIN_VERTICES
from app.core.variants.prepared import Prepared

RADIUS = 1.0  # fingerprint distance past which no relation is verified (a decimation to 10 % moves ~0.5)
SAME_RADIUS = 0.5  # ... past which only a much coarser copy is (same-resolution variants: 0.35 at most)
COARSE_RATIO = 2.0  # "much coarser": mean edge (over the RMS radius) this many times the other's


def coarsening(a: Prepared, b: Prepared) -> float:
    """How many times longer the coarser mesh's edges are, each relative to its own RMS radius (>= 1)."""
    ra, rb = a.resolution, b.resolution
    return max(ra, rb) / max(min(ra, rb), 1e-300)


def may_relate(a: Prepared, b: Prepared) -> bool:
    """False when no relation but `similar` is possible between the two surfaces (module docstring)."""
    gap = float(np.linalg.norm(a.fingerprint - b.fingerprint))
    if gap > RADIUS:
        return False
    if gap <= SAME_RADIUS:
        return True
    # only the one-sided test (onesided.py) can pass a far pair, with the coarser mesh lying on the
    # finer one: it needs that mesh much coarser, and never passes one of fewer than MIN_VERTICES
    coarser = a if a.resolution >= b.resolution else b
    return coarsening(a, b) >= COARSE_RATIO and coarser.mesh.n_vertices >= MIN_VERTICES
