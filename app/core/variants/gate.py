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
"""

from __future__ import annotations

import numpy as np

from app.core.variants.onesided import MIN_VERTICES
from app.core.variants.prepared import Prepared

RADIUS = 1.0  # fingerprint distance past which no relation is verified (a decimation to 10 %: 0.89)
SAME_RADIUS = 0.5  # ... past which only a much coarser copy is (same-resolution variants: 0.426 at most)
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
