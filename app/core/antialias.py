"""Anti-aliasing before decimation: a low-pass at the input's own resolution.

Quadric decimation keeps vertices on the input's planes, so vertex noise of a 50k-vertex scan survives
into the 1,000-vertex canonical mesh at full amplitude (aliasing), where only strong smoothing removes
it, and that smoothing also erases real detail. Smoothing first, at full resolution, with a cutoff
at the canonical mesh's own edge length removes the frequencies the canonical mesh cannot represent
(almost all of white noise's energy: a fraction 1 - target/n of it) and leaves what it can.

The filter is one implicit diffusion step (backward Euler) on the capped-area vertex graph
(app.core.smoothing): (D + t (D - C)) x' = D x, C the symmetric edge weights, D their row sums.
It is symmetric positive definite, so conjugate gradients solve it in ~sqrt(1 + 2t) iterations.
The diffusion time t is in steps of the input's own edges: a random walk of t steps spreads
~sqrt(t) edges, so t = (length * h_canonical / h_input)^2 = length^2 * n_input / target, scale-free.

Its strength ramps with the decimation ratio r = n_input / target (`ramp_length`): a mild decimation
(2-4x) aliases little, and there the filter only rounds the query against a collection that was
subdivided or decimated as mildly (SHREC'11's re-triangulated copies, 3,000-vertex shapes), so the
length grows linearly from 0 at r = start to `length` at r = full (docs/results.md, "Full-resolution
columns and anti-aliasing").
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from app.core.mesh import Mesh
from app.core.smoothing import edge_area_weights


def ramp_length(length: float, ratio: float, ramp: tuple[float, float]) -> float:
    """The filter length for a decimation by `ratio` (n_input / target): 0 up to ramp[0], `length`
    from ramp[1] on, linear between (a step at ramp[0] when the two are equal)."""
    start, full = ramp
    if ratio >= full:
        return length
    if ratio <= start:
        return 0.0
    return length * (ratio - start) / (full - start)


def prefilter(mesh: Mesh, target_vertices: int, length: float) -> Mesh:
    """Implicit diffusion of the vertex positions over `length` canonical edge lengths, for a mesh
    about to be decimated to `target_vertices` (the caller ramps `length`: resolution.simplify, which
    knows the input's ratio before any clustering). vertices (n, 3) move, faces (f, 3) are kept; a
    mesh not above the target, or length 0, is returned as is."""
    n = mesh.n_vertices
    if length <= 0 or target_vertices <= 0 or n <= target_vertices:
        return mesh
    t = length**2 * n / target_vertices
    c = edge_area_weights(mesh, capped=True)
    c.setdiag(0)
    c.eliminate_zeros()
    d = np.asarray(c.sum(axis=1)).ravel()
    isolated = d <= 0  # no face of positive area: the vertex keeps its position (identity row)
    d_safe = np.where(isolated, 1.0, d)
    a = (sp.diags(np.where(isolated, 1.0, d * (1.0 + t))) - t * c).tocsr()  # D + t (D - C), SPD
    b = d_safe[:, None] * mesh.vertices  # (n, 3)
    jacobi = sp.diags(1.0 / a.diagonal())
    out = np.empty_like(mesh.vertices)
    for axis in range(3):
        x, info = spla.cg(a, b[:, axis], x0=mesh.vertices[:, axis], rtol=1e-8, maxiter=2000, M=jacobi)
        out[:, axis] = x if info == 0 and np.all(np.isfinite(x)) else mesh.vertices[:, axis]
    return Mesh(out, mesh.faces)
