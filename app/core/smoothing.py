"""Taubin λ|μ smoothing with capped area weights (the default), other intrinsic weights, or uniform ones.

Taubin's filter alternates a shrinking step x <- x + λ (W x - x) and an inflating one with μ < 0, W a
row-stochastic averaging of each vertex's neighbours: low frequencies pass, vertex noise does not, and
the shape does not shrink as plain Laplacian smoothing does. What W is decides what the filter sees:

- "intrinsic": the cotangent weights of the intrinsic Delaunay triangulation of the same
  surface (laplacian.intrinsic_delaunay_laplacian), all ≥ 0. They are a property of the surface's
  metric, not of how its vertices are connected: a linear function is its own average, so the
  interior of a flat patch does not move whatever its triangulation, and a vertex moves by the
  surface's curvature, not by the count of its neighbours.
- "cotangent": the extrinsic cotangent weights, negative ones (non-Delaunay edges) clipped to 0.
  On the long thin triangles of a decimated mesh most weights are clipped, and the clipped filter no
  longer reproduces a plane.
- "area": each neighbour j by the area of the one or two faces on the edge ij. The averaging runs
  over the surface of the vertex's star rather than over its count of neighbours, so a neighbour that
  stands for more surface pulls more; the vertex still slides along the surface as under uniform
  weights. Face areas are intrinsic (they follow from the edge lengths). It retrieves best on organic
  shapes, but a decimated CAD part's few large faces drag their vertices across it, so it loses on
  rigid parts: an option, not the default.
- "capped-area" (the default): the same, each face's area capped at the mesh's median face area, so a
  face larger than usual counts as a usual one: smaller faces (a crowded side) still count for less,
  and a decimated CAD part's few large faces no longer drag their vertices. It is the weighting that
  holds on every collection measured, noisy queries included.
- "uniform": each neighbour by 1 (trimesh.smoothing.filter_taubin). It depends on the triangulation:
  on an irregular mesh it slides vertices along the surface towards their neighbours' centroid and
  changes the shape by where the vertices were. That slide is also why it does well across
  triangulations: two triangulations of one surface come out more alike.

The measurements behind these sentences are in docs/results.md. `steps` counts single steps, λ then μ
then λ ..., for every weighting (trimesh's convention): 10 steps are 5 λ|μ pairs. The weights are
computed once, from the input, and are scale-free; the update is linear in the coordinates, so every
weighting commutes with rotation, translation, uniform scale and vertex order.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import trimesh

from app.core.laplacian import cotangent_laplacian, intrinsic_delaunay_laplacian
from app.core.mesh import Mesh

WEIGHTS = ("intrinsic", "cotangent", "area", "capped-area", "uniform")
AVERAGED = tuple(w for w in WEIGHTS if w != "uniform")  # what averaging_operator builds; uniform is trimesh's
LAMBDA, MU = 0.5, -0.53  # Taubin's pass band: k_PB = 1/λ + 1/μ ≈ 0.11


def averaging_operator(mesh: Mesh, weights: str) -> tuple[sp.csr_matrix, np.ndarray]:
    """(n, n) row-stochastic averaging operator W and (n,) bool "has neighbours" (a vertex without a
    positive weight keeps its position).

    W_ij ∝ max(-L_ij, 0) for the named Laplacian L, "intrinsic" or "cotangent" (the intrinsic one has
    no negative weight to clip; a negative extrinsic weight would push a vertex away from its
    neighbour); W_ij ∝ the area of the faces on edge ij ("area"). The uniform filter is trimesh's
    (taubin).
    """
    if weights in ("intrinsic", "cotangent"):
        laplace = intrinsic_delaunay_laplacian if weights == "intrinsic" else cotangent_laplacian
        stiffness, _ = laplace(mesh.vertices, mesh.faces)
        w = (-stiffness).tocsr()
    elif weights in ("area", "capped-area"):
        w = edge_area_weights(mesh, capped=weights == "capped-area")
    else:
        raise ValueError(f"weights must be one of {', '.join(AVERAGED)}, not {weights!r}")
    w.setdiag(0)
    w.data = np.maximum(w.data, 0.0)
    w.eliminate_zeros()
    rows = np.asarray(w.sum(axis=1)).ravel()
    has = rows > 0
    return (sp.diags(np.where(has, 1.0 / np.where(has, rows, 1.0), 0.0)) @ w).tocsr(), has


def edge_area_weights(mesh: Mesh, capped: bool = False) -> sp.csr_matrix:
    """(n, n) weights on the mesh's edges: W_ij = the summed area of the one or two faces on edge ij,
    each face's area capped at the mesh's median face area when `capped`: a face smaller than usual
    counts for less, one larger than usual for no more than a usual one."""
    f, n = mesh.faces, mesh.n_vertices
    areas = mesh.face_areas()
    if capped and len(areas):
        areas = np.minimum(areas, np.median(areas))
    rows = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0]])  # each edge both ways
    cols = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2]])
    return sp.csr_matrix((np.tile(areas, 6), (rows, cols)), shape=(n, n))  # duplicates sum


def taubin(mesh: Mesh, steps: int, weights: str) -> Mesh:
    """`steps` alternating λ and μ steps x <- x + s (W x - x), W = averaging_operator(mesh, weights)
    from the input geometry. vertices (n, 3) move, faces (f, 3) are kept; 0 steps returns `mesh`."""
    if weights not in WEIGHTS:
        raise ValueError(f"weights must be one of {', '.join(WEIGHTS)}, not {weights!r}")
    if steps <= 0:
        return mesh
    if weights == "uniform":  # the library's own filter, so uniform descriptions stay what they were
        tm = trimesh.Trimesh(mesh.vertices.copy(), mesh.faces, process=False)
        trimesh.smoothing.filter_taubin(tm, lamb=LAMBDA, nu=-MU, iterations=steps)
        return Mesh(np.asarray(tm.vertices, dtype=np.float64), mesh.faces)
    w, has = averaging_operator(mesh, weights)
    x = mesh.vertices.copy()
    for step in range(steps):
        s = LAMBDA if step % 2 == 0 else MU
        x = x + s * np.where(has[:, None], w @ x - x, 0.0)  # (n, 3)
    return Mesh(x, mesh.faces)
