"""Candidate similarities for "the same triangles" from vertices that can be told apart on their own.

The surface fit (ICP from the principal axes) cannot choose among the turns of a shape whose surface
is (nearly) symmetric: a faceted cake, two balls, a tray. When its vertices are renumbered, the fit
may end on a symmetric pose where every vertex lands on a vertex but the triangles differ, or a
fraction of a facet off. The triangulation itself usually breaks the symmetry: a vertex's degree,
its incident edge lengths and its distance from the area centroid, all over the RMS radius, are the
same for the same vertex of a moved, rescaled, mirrored or renumbered copy (to rounding) and often
differ between the vertices a symmetry swaps. Vertices whose descriptor matches exactly one vertex of
the other mesh anchor a fit; relate's exact test (relate._exact) still decides.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from app.core.variants.align import Similarity, umeyama
from app.core.variants.prepared import Prepared

MATCH = 1e-5  # descriptors of the same vertex agree to float rounding (float32 files: ~1e-7) ...
APART = 1e-3  # ... and the next-nearest vertex of the other mesh is this far: an unambiguous match
MIN_ANCHORS = 4
TRIES = 6  # random subsets of the anchors tried after all of them (a few coincidental matches)
SUBSET = 6


def descriptors(p: Prepared) -> np.ndarray:
    """(n, 7) per vertex: degree, distance from the area centroid, shortest, mean and longest
    incident edge, lengths over the RMS radius (an unused vertex: degree 0, edges 0), and the sum
    and the sum of squares of its neighbours' degrees (a regular grid's vertices differ there only)."""
    v, f = p.mesh.vertices, p.mesh.faces
    n = len(v)
    edges = np.unique(np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)  # (e, 2)
    length = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1) / p.frame.radius
    ends, both = edges.ravel(), np.repeat(length, 2)
    degree = np.bincount(ends, minlength=n).astype(float)
    total = np.bincount(ends, weights=both, minlength=n)
    shortest = np.full(n, np.inf)
    longest = np.zeros(n)
    np.minimum.at(shortest, ends, both)
    np.maximum.at(longest, ends, both)
    shortest[degree == 0] = 0.0
    radial = np.linalg.norm(v - p.frame.centroid, axis=1) / p.frame.radius
    other = np.concatenate([edges[:, 1], edges[:, 0]])  # the neighbour at the other end of each
    near = np.bincount(ends.reshape(-1, 2).T.ravel(), weights=degree[other], minlength=n)
    near2 = np.bincount(ends.reshape(-1, 2).T.ravel(), weights=degree[other] ** 2, minlength=n)
    return np.stack([degree, radial, shortest, total / np.maximum(degree, 1), longest, near / 8.0,
                     near2 / 64.0], axis=1)


def anchored_fits(a: Prepared, b: Prepared, rng_seed: int = 0) -> list[Similarity]:
    """Similarities (proper and mirrored) fitted on a's vertices matched unambiguously to b's by
    descriptor: first on all the anchors, then on TRIES random subsets of SUBSET of them. Empty when
    fewer than MIN_ANCHORS vertices match so."""
    da, db = descriptors(a), descriptors(b)
    if len(db) < 2:
        return []
    dist, idx = cKDTree(db).query(da, k=2, workers=1)  # (n_a, 2)
    own = cKDTree(da).query(da, k=2, workers=1)[0][:, 1]  # a's own next-nearest: not ambiguous in a either
    sure = np.flatnonzero((dist[:, 0] <= MATCH) & (dist[:, 1] > APART) & (own > APART))
    if len(sure) < MIN_ANCHORS:
        return []
    src, dst = a.mesh.vertices[sure], b.mesh.vertices[idx[sure, 0]]
    rng = np.random.default_rng(rng_seed)
    subsets = [np.arange(len(sure))] + [rng.choice(len(sure), min(SUBSET, len(sure)), replace=False)
                                        for _ in range(TRIES if len(sure) > SUBSET else 0)]
    return [umeyama(src[s], dst[s], mirrored=m) for s in subsets for m in (False, True)]
