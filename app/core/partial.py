"""Local signatures for partial matching: does a piece's surface occur in a model, and how much of it?

A global histogram sees a cut shape as another shape; a piece is better compared point by point, with a
signature of each point's neighbourhood that neither the cut nor the change of scale alters:
- **fixed absolute times** on the unit-area mesh, log-spaced by a ratio `r`: K_t(x, x) at short times
  depends on the neighbourhood of x within ~√t, not on the mesh's own λ_2 or λ_k (which a cut changes);
- **scale by a shift**: a piece normalised to unit area is its whole's surface scaled by s = 1/√f (f the
  kept share), and K_{s²t}(sx, sx) = K_t(x, x) / s². The slopes d log K / d log t at the grid's times
  drop the 1/s² and turn s into a shift of the grid by log(s²) / log(r) steps: a query is signed on a
  longer grid, and each scale hypothesis is one window of it (Bronstein & Kokkinos 2010 make this
  shift invariant by a Fourier modulus; a window keeps the scale, which is what the reverse score needs);
- **the rim**: heat reflects at a free boundary (Neumann), so the slope at time t is only trusted at
  points farther than `rim_factor`·√t from the rim; each point keeps the prefix of its times that is
  trusted, and points with none are dropped.
A model stores `points` samples (farthest-point, each standing for the area nearest to it), a query is
sampled the same way; both sides are small (a few hundred points x about 16 slopes, float32).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from app.core.cleaning import edge_uses
from app.core.spectrum import Spectrum


@dataclass(frozen=True)
class LocalParams:
    """Grid of the local signature; the model's J = `slopes` + 1 times, the query's `shifts` more."""

    t0: float = 2e-3  # shortest time on the unit-area mesh (~(2 edges)² at 1000 vertices)
    ratio: float = 2.0 ** 0.25  # consecutive times; one shift = a kept share of 1/ratio
    slopes: int = 16
    shifts: int = 6  # scale hypotheses 0..shifts-1: kept share down to ratio^-(shifts-1) (~0.42)
    points: int = 256
    rim_factor: float = 1.0  # 2 and 3 retrieved worse on SHREC pieces (docs/partial.md)

    def times(self, extra: int = 0) -> np.ndarray:
        """(slopes + 1 + extra,) the times, ascending."""
        return self.t0 * self.ratio ** np.arange(self.slopes + 1 + extra)


@dataclass(frozen=True)
class LocalSignature:
    """Sampled local signature of one shape.

    slopes : (p, J') float32, d log K / d log t between consecutive grid times (J' = slopes for a model,
             slopes + shifts - 1 for a query signed on the longer grid)
    area   : (p,) float32, share of the shape's area each sample stands for (sum 1)
    valid  : (p,) int16, how many leading slopes of each sample the rim leaves trusted (J' if no rim)
    rim    : float, length of the free boundary over √area (0 for a closed surface)
    vertex : (p,) int32, the vertex each sample is, in the described mesh (the description's vertices,
             which the explain view draws); None in descriptions saved before it was stored
    level  : (p,) float32, log(t0·K_t0(x, x)) at the grid's first time: the heat's level, which scale does
             not change (a surface scaled by s read at s²t), where the slopes say only how it falls; the
             level at a later grid time is this plus the cumulated (slope + 1)·log(ratio). None in
             descriptions saved before it was stored
    surface: (n, 3) float16, the described mesh's vertices at unit area (the piece's own for one solved on
             its double), which `vertex` indexes: where the samples lie, for a fit of a piece onto a model
             (app.core.piece_fit); None in descriptions saved before it was stored
    """

    slopes: np.ndarray
    area: np.ndarray
    valid: np.ndarray
    rim: float
    vertex: np.ndarray | None = None
    level: np.ndarray | None = None
    surface: np.ndarray | None = None


def log_heat(spectrum: Spectrum, times: np.ndarray) -> np.ndarray:
    """(n, len(times)) log K_t(x, x), K_t(x, x) = Σ_i exp(-λ_i t) φ_i(x)²."""
    decay = np.exp(-np.outer(spectrum.eigenvalues, times))  # (k, T)
    k = (spectrum.eigenvectors ** 2) @ decay  # (n, T)
    return np.log(np.maximum(k, np.finfo(float).tiny))


def log_slopes(spectrum: Spectrum, times: np.ndarray, logk: np.ndarray | None = None) -> np.ndarray:
    """(n, len(times) - 1) d log K_t(x, x) / d log t between consecutive times (finite differences);
    logk: log_heat(spectrum, times) when the caller has it.

    On a flat region K ≈ 1/(4πt) and the slope is -1, on a thin tube it tends to -1/2, and it rises to 0
    as heat fills a closed shape.
    """
    logk = log_heat(spectrum, times) if logk is None else logk
    return np.diff(logk, axis=1) / np.diff(np.log(times))


def farthest_points(vertices: np.ndarray, count: int, start: int = 0) -> np.ndarray:
    """(min(count, n),) indices of a farthest-point sample of vertices (n, 3), from vertex `start`."""
    n = len(vertices)
    count = min(count, n)
    chosen = np.empty(count, dtype=np.int64)
    chosen[0] = start
    dist = np.linalg.norm(vertices - vertices[start], axis=1)
    for i in range(1, count):
        chosen[i] = int(np.argmax(dist))
        dist = np.minimum(dist, np.linalg.norm(vertices - vertices[chosen[i]], axis=1))
    return chosen


def rim_distance(vertices: np.ndarray, rim: np.ndarray) -> np.ndarray:
    """(n,) Euclidean distance of each vertex to the nearest rim vertex (rim (n,) bool); inf if none.

    Euclidean is at most geodesic, so trusting a slope beyond it never trusts one too close."""
    if not rim.any():
        return np.full(len(vertices), np.inf)
    return cKDTree(vertices[rim]).query(vertices)[0]


def free_boundary(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(n,) bool: the vertices on an edge of one face only. faces (f, 3).

    Every such vertex, whether or not its loop is a simple one: a cut along the triangulation leaves
    pinched rims (a vertex on the loop twice) that a loop walk skips."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    out = np.zeros(n_vertices, dtype=bool)
    out[uniq[counts == 1].ravel()] = True
    return out


def rim_length(vertices: np.ndarray, faces: np.ndarray, rim: np.ndarray) -> float:
    """Length of the rim over √area: the edges of exactly one face of the surface, the caps of closed
    holes left out (a cap's centre is a rim vertex whose neighbours are all rim; a cap's faces are those
    around it). rim (n,) bool, faces (f, 3).

    It is what tells a piece from a whole: a closed surface has none, and a hole closed by a cap still
    counts, as the cap is not the surface that was there. An edge between two rim vertices that two
    faces of the surface share is not rim: two punctures side by side are joined by such an edge."""
    if not rim.any():
        return 0.0
    edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    # a rim vertex with a neighbour off the rim is on a loop; one with none is a cap's centre, unless no
    # rim vertex has such a neighbour: a surface that is all rim (a strip) has loops and no caps
    off = np.zeros(len(vertices), dtype=bool)
    for a, b in ((0, 1), (1, 0)):
        off[edges[~rim[edges[:, b]], a]] = True
    centre = rim & ~off if off[rim].any() else np.zeros(len(vertices), dtype=bool)
    surface = faces[~centre[faces].any(axis=1)]
    # the surface's free edges, open or capped
    once = surface[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)[edge_uses(surface)[1] == 1]
    lengths = np.linalg.norm(vertices[once[:, 0]] - vertices[once[:, 1]], axis=1)
    area = 0.5 * np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                         vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1).sum()
    return float(lengths.sum() / np.sqrt(area))


def local_signature(spectrum: Spectrum, vertices: np.ndarray, faces: np.ndarray, mass: np.ndarray,
                    rim: np.ndarray, params: LocalParams, query: bool = True,
                    measured_rim: float | None = None) -> LocalSignature:
    """Sampled slopes of a mesh. vertices (n, 3) of unit total area, faces (f, 3), mass (n,) lumped
    areas, rim (n,) bool (the vertices on a free boundary or on the cap of a closed hole). query: the
    longer grid (descriptions always keep it, as a model reads its leading slopes). measured_rim: the
    rim's length where the caller measured it (the pipeline: before smoothing, which pulls punctures
    open); None: rim_length of these vertices."""
    times = params.times(params.shifts - 1 if query else 0)
    logk = log_heat(spectrum, times)  # (n, J' + 1)
    slopes = log_slopes(spectrum, times, logk)  # (n, J')
    # slope j spans times j..j+1: trusted where the rim is farther than rim_factor·√t_{j+1}
    reach = params.rim_factor * np.sqrt(times[1:])  # (J',)
    valid_n = np.searchsorted(reach, rim_distance(vertices, rim), side="left")  # (n,) leading count
    keep = farthest_points(vertices, params.points)
    owner = cKDTree(vertices[keep]).query(vertices)[1]  # (n,) nearest sample of each vertex
    area = np.bincount(owner, weights=mass, minlength=len(keep))
    return LocalSignature(slopes=slopes[keep].astype(np.float32),
                          area=(area / area.sum()).astype(np.float32),
                          valid=valid_n[keep].astype(np.int16),
                          rim=rim_length(vertices, faces, rim) if measured_rim is None else measured_rim,
                          vertex=keep.astype(np.int32),
                          level=(logk[keep, 0] + np.log(times[0])).astype(np.float32))
