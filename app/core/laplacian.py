"""Discrete Laplace–Beltrami operator: cotangent stiffness and lumped (barycentric) mass.

With L the stiffness and M the mass, the generalised problem L φ = λ M φ approximates Δφ = λφ
(Pinkall & Polthier 1993, the discretisation the paper uses).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from app.core.meshdata import Mesh

LAPLACIANS = ("cotangent", "intrinsic")
# edge lengths are padded by this fraction of the mean edge length before the intrinsic flips, so a
# zero-area triangle (common after decimation) gets finite cotangents (Sharp & Crane 2020, §4.5)
MOLLIFY = 1e-5
Operators = tuple[sp.csr_matrix, sp.dia_matrix]  # (stiffness L, lumped mass M)


def cotangent_laplacian(vertices: np.ndarray, faces: np.ndarray) -> tuple[sp.csr_matrix, sp.dia_matrix]:
    """Return (L, M) for a triangle mesh.

    vertices : (n, 3) float
    faces    : (f, 3) int
    L : (n, n) csr, symmetric positive semi-definite, rows sum to 0;
        L_ij = -(cot α_ij + cot β_ij) / 2 for an edge ij, L_ii = -Σ_j L_ij
    M : (n, n) diagonal, M_ii = one third of the area of the faces around i
    """
    n = vertices.shape[0]
    tri = vertices[faces]  # (f, 3, 3)
    # edge opposite corner c: from corner c+1 to c+2
    e0 = tri[:, 2] - tri[:, 1]
    e1 = tri[:, 0] - tri[:, 2]
    e2 = tri[:, 1] - tri[:, 0]
    double_area = np.linalg.norm(np.cross(e2, -e1), axis=1)  # (f,)
    safe = np.maximum(double_area, np.finfo(float).tiny)
    # cot of the angle at each corner = <a, b> / |a x b|, with a, b the two edges leaving the corner
    cot0 = -np.einsum("ij,ij->i", e1, e2) / safe
    cot1 = -np.einsum("ij,ij->i", e2, e0) / safe
    cot2 = -np.einsum("ij,ij->i", e0, e1) / safe
    i, j, k = faces[:, 0], faces[:, 1], faces[:, 2]
    rows = np.concatenate([j, k, k, i, i, j])
    cols = np.concatenate([k, j, i, k, j, i])
    vals = -0.5 * np.concatenate([cot0, cot0, cot1, cot1, cot2, cot2])
    off = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    diag = -np.asarray(off.sum(axis=1)).ravel()
    stiffness = (off + sp.diags(diag)).tocsr()
    mass = lumped_mass(n, faces, 0.5 * double_area)
    return stiffness, mass


def lumped_mass(n: int, faces: np.ndarray, face_areas: np.ndarray) -> sp.dia_matrix:
    """(n, n) diagonal mass: a third of each incident face's area per vertex."""
    m = np.bincount(faces.ravel(), weights=np.repeat(face_areas / 3.0, 3), minlength=n)
    return sp.diags(m)


def intrinsic_delaunay_laplacian(vertices: np.ndarray, faces: np.ndarray) -> Operators:
    """(L, M) of the intrinsic Delaunay triangulation of the same surface (robust-laplacian).

    Edges are flipped intrinsically (lengths only; the surface and its vertices do not move) until
    every edge is Delaunay, then the cotangent formula is applied. On a closed mesh that is already
    Delaunay this is cotangent_laplacian; along a boundary, the tufted cover (two sheets glued at the
    boundary, which keeps the Neumann condition) lets boundary edges flip too. Why: on the long thin
    triangles that quadric decimation leaves on flat facets, the extrinsic cotangent weights inflate
    the top of the spectrum and make λ_k depend on the triangulation (λ_300 differs by 1.50× between
    two triangulations of one SHREC'11 surface, 1.09× here). Non-manifold input goes through the
    tufted cover as well (Sharp & Crane 2020).

    vertices : (n, 3) float
    faces    : (f, 3) int
    L : (n, n) csr, symmetric positive semi-definite, rows sum to 0, off-diagonal entries ≤ 0
    M : (n, n) diagonal lumped mass, as cotangent_laplacian's (a third of each face's area per vertex)
    """
    import robust_laplacian  # a compiled extension: imported only by the describe processes that use it

    stiffness, _ = robust_laplacian.mesh_laplacian(
        np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64),
        mollify_factor=MOLLIFY)
    # the mass stays the input's barycentric lumping (the same quadrature of the same surface): the
    # intrinsic triangulation can leave a vertex between slivers only, with 1e-6 of the mean mass,
    # and such a vertex made λ_0 come out at 2e-3 instead of 0 on a decimated SHREC'11 mesh
    areas = Mesh(vertices, faces).face_areas()
    return sp.csr_matrix(stiffness), lumped_mass(vertices.shape[0], faces, areas)


def laplacian(vertices: np.ndarray, faces: np.ndarray, kind: str = "cotangent") -> Operators:
    """(L, M) by name: "cotangent" (the paper's) or "intrinsic" (intrinsic Delaunay)."""
    if kind == "intrinsic":
        return intrinsic_delaunay_laplacian(vertices, faces)
    if kind == "cotangent":
        return cotangent_laplacian(vertices, faces)
    raise ValueError(f"laplacian must be one of {', '.join(LAPLACIANS)}, not {kind!r}")
