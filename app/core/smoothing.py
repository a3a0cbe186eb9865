"""Intrinsic smoothing: Taubin's λ|μ filter with cotangent weights.

Uniform-weight Taubin smoothing (resolution.smooth) averages a vertex with its neighbours by count: on
an irregular, decimated mesh it moves vertices along the surface and distorts the shape (it cost 6
points of mAP on decimated scans, issue 11). Here each neighbour counts by the cotangent weight of
the shared edge, the discrete Laplace–Beltrami operator of the surface: the filter depends on the
geometry, not on how many edges meet at a vertex. It keeps Taubin's band-pass (a shrinking λ step, an
inflating μ step: low frequencies pass, vertex noise does not). The weights are scale-free and the
update is linear in the coordinates, so it commutes with rotation, translation, uniform scale and
vertex order. On a flat patch whose edges are Delaunay every weight is positive and a linear function
is reproduced exactly: the interior of a plane does not move.

An option (DescribeParams.smoothing_weights="cotangent"), not the default: on SHREC'11's triangulation
and noise variants it recovered 8 of the 31 and 1.2 of the 6.2 points that dropping smoothing costs,
where uniform Taubin recovers all of them (docs/results.md, "Defaults across datasets").
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from app.core.laplacian import cotangent_laplacian
from app.core.mesh import Mesh

WEIGHTS = ("cotangent", "uniform")


def cotangent_weights(mesh: Mesh) -> tuple[sp.csr_matrix, np.ndarray]:
    """(n, n) row-stochastic averaging operator W and (n,) bool "has neighbours".

    W_ij ∝ max(cot α_ij + cot β_ij, 0): a non-Delaunay edge (negative weight) would push a vertex
    away from its neighbour, so it is left out; a vertex with no positive weight keeps its position.
    """
    stiffness, _ = cotangent_laplacian(mesh.vertices, mesh.faces)
    w = (-stiffness).tocsr()
    w.setdiag(0)
    w.data = np.maximum(w.data, 0.0)
    w.eliminate_zeros()
    rows = np.asarray(w.sum(axis=1)).ravel()
    has = rows > 0
    return (sp.diags(np.where(has, 1.0 / np.where(has, rows, 1.0), 0.0)) @ w).tocsr(), has


def cotangent_taubin(mesh: Mesh, iterations: int, lamb: float = 0.5, mu: float = -0.53) -> Mesh:
    """`iterations` λ|μ pairs: x <- x + s (W x - x), s = λ then μ; W from the input geometry.
    vertices (n, 3) move, faces (f, 3) are kept."""
    if iterations <= 0:
        return mesh
    w, has = cotangent_weights(mesh)
    x = mesh.vertices.copy()
    for _ in range(iterations):
        for step in (lamb, mu):
            x = x + step * np.where(has[:, None], w @ x - x, 0.0)  # (n, 3)
    return Mesh(x, mesh.faces)
