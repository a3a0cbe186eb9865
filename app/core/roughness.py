"""How rough a surface is at its own sampling: the measure that decides how much smoothing it needs.

Noise moves each vertex off the surface independently of its neighbours; shape moves a vertex together
with its neighbours. So the normal displacement of a vertex from the average of its neighbours,
δ_i = n_i · (x_i - (W x)_i), is smooth over a smooth surface whatever its curvature (it follows the
mean curvature, κ h² / 4 at edge length h), and jumps from vertex to vertex under noise or on the
facets that a coarse mesh's subdivision leaves. The roughness is what is left of δ once its own
neighbourhood average is taken away, ρ_i = |δ_i - (W δ)_i|, as a multiple of the mesh's median edge
length; its median over the vertices ignores the few vertices of a small sharp part (an ear, a
fingertip) that a clean surface also has.

The measure is scale-free and unchanged by rigid motion and vertex order (W is the capped-area
averaging of app.core.smoothing, built from face areas only).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from app.core.cleaning import edge_uses
from app.core.decimation import face_normals, vertex_normal_sums
from app.core.mesh import Mesh
from app.core.smoothing import LAMBDA, MU, averaging_operator


def vertex_normals(mesh: Mesh) -> np.ndarray:
    """(n, 3) unit area-weighted vertex normals (zero for a vertex without faces)."""
    normals = vertex_normal_sums(mesh, face_normals(mesh))
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, norm, out=np.zeros_like(normals), where=norm > 0)


def median_edge_length(mesh: Mesh) -> float:
    v, f = mesh.vertices, mesh.faces
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    return float(np.median(np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)))


def normal_displacement(mesh: Mesh, w: sp.csr_matrix) -> np.ndarray:
    """(n,) δ = n · (x - W x): each vertex's offset from its neighbours' average (W (n, n), row-stochastic)
    along its normal."""
    x = mesh.vertices
    return np.einsum("ij,ij->i", vertex_normals(mesh), x - w @ x)


def roughness(mesh: Mesh, averaging: tuple[sp.csr_matrix, np.ndarray] | None = None) -> float:
    """Median |δ - W δ| / median edge length (module docstring); 0 for a mesh without faces.

    averaging : (W (n, n), has (n,) bool) as averaging_operator(mesh, "capped-area") gives; a caller
    that smooths with a fixed W (taubin) passes it, so the measure follows the same neighbourhoods.
    """
    if len(mesh.faces) == 0:
        return 0.0
    w, has = averaging if averaging is not None else averaging_operator(mesh, "capped-area")
    delta = normal_displacement(mesh, w)
    rough = np.abs(delta - w @ delta)[has]
    edge = median_edge_length(mesh)
    if edge <= 0 or rough.size == 0:
        return 0.0
    return float(np.median(rough) / edge)


def smooth_until(mesh: Mesh, target: float, max_steps: int, weights: str = "capped-area") -> tuple[Mesh, int]:
    """Taubin λ|μ pairs (app.core.smoothing.taubin's steps, W from the input) until roughness <= target
    or max_steps steps are done: each mesh smoothed only as much as its own noise needs.
    vertices (n, 3) move, faces (f, 3) are kept. Returns the mesh and the steps taken (even)."""
    w, has = averaging_operator(mesh, weights)
    x = mesh.vertices.copy()
    steps = 0
    while steps + 2 <= max_steps and roughness(Mesh(x, mesh.faces), (w, has)) > target:
        for s in (LAMBDA, MU):
            x = x + s * np.where(has[:, None], w @ x - x, 0.0)  # (n, 3)
        steps += 2
    return (Mesh(x, mesh.faces) if steps else mesh), steps


# below this many vertices a mesh is all corners (17 of the 109 readable realworld meshes read negative,
# most of them 4-26-vertex boxes and tetrahedra): no vertex noise can be told from its shape
NOISE_MIN_VERTICES = 100


def displacement_correlation(mesh: Mesh) -> float:
    """corr(δ, W δ) over the vertices with neighbours (module docstring's δ, W capped-area): how much a
    vertex's normal displacement follows its neighbours'. NaN when undefined (no faces, δ constant) or
    not measurable: fewer than NOISE_MIN_VERTICES vertices with neighbours, where every vertex is a
    corner of the shape (a cube's 8 read -1) and the correlation's own error is ±0.1 or more.

    Vertex-scale noise makes it negative: δ_i holds the vertex's own offset, and each neighbour's δ_j
    holds the same offset with a negative weight (x_i is in the average it is measured from), so the two
    are anti-correlated (≈ -0.5 under white noise). A smooth surface's δ follows its mean curvature,
    which changes slowly: ≈ +0.8 at any resolution. A CAD part's creases fall in between (≈ 0.1-0.8);
    noise far larger than an edge folds the surface and also reads in between (docs/results.md).
    Unlike `roughness`, it needs no scale: the sign says whether the mesh's finest scale is noise.
    """
    if len(mesh.faces) == 0 or mesh.n_vertices < NOISE_MIN_VERTICES:
        return float("nan")
    w, has = averaging_operator(mesh, "capped-area")
    delta = normal_displacement(mesh, w)
    d, wd = delta[has], (w @ delta)[has]
    if d.size < NOISE_MIN_VERTICES or np.ptp(d) == 0 or np.ptp(wd) == 0:
        return float("nan")
    with np.errstate(invalid="ignore", divide="ignore"):
        return float(np.corrcoef(d, wd)[0, 1])


FOLD_ANGLE = 2 * np.pi / 3  # two faces whose normals are more than 120 degrees apart fold the surface back
FOLDED = 0.3  # a fold share from which a mesh counts as heavily noisy (benchmarks.heavy_noise)


def watertight(mesh: Mesh) -> bool:
    """Every edge on exactly two faces."""
    return bool(len(mesh.faces)) and bool((edge_uses(mesh.faces)[1] == 2).all())


def fold_share(mesh: Mesh) -> float:
    """Share of the edges with exactly two faces whose normals are more than FOLD_ANGLE apart: 0 on a
    smooth or CAD surface (at most 0.06 over every clean column and the realworld corpus), about half
    under noise of a few edges, which scrambles the triangles. NaN under NOISE_MIN_VERTICES vertices
    (a tetrahedron's edges read 1/3) or with no such edge."""
    if mesh.n_vertices < NOISE_MIN_VERTICES or not len(mesh.faces):
        return float("nan")
    normals = face_normals(mesh)
    normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    edge, uses = edge_uses(mesh.faces)
    order = np.argsort(edge, kind="stable")  # the face-edge rows grouped by edge
    rows = order[uses[order] == 2].reshape(-1, 2)  # an interior edge's two rows are neighbours in order
    if not len(rows):
        return float("nan")
    cos = (normals[rows[:, 0] // 3] * normals[rows[:, 1] // 3]).sum(axis=1)
    return float((cos < np.cos(FOLD_ANGLE)).mean())
