"""Surface integrals and samples shared by the variant fingerprint and the verification.

Everything here is weighted by area, so it describes the surface rather than its triangulation:
a remeshed or decimated copy of a surface has (nearly) the same moments and samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.cleaning import face_components
from app.core.meshdata import Mesh

SAMPLE_SEED = 0  # a fixed stream: the same mesh always gives the same samples and fingerprint
MAX_COMPONENTS = 2000  # the box-overlap test below is quadratic in the number of components


@dataclass(frozen=True)
class Moments:
    """Area-weighted surface moments.

    area     : total area A
    centroid : (3,) area centroid c
    cov      : (3, 3) (1/A) integral of (x - c)(x - c)^T dA
    """

    area: float
    centroid: np.ndarray
    cov: np.ndarray

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Eigenvalues (3,) descending and eigenvectors (3, 3) as columns, right-handed (det +1)."""
        values, vectors = np.linalg.eigh(self.cov)
        order = np.argsort(values)[::-1]
        values, vectors = values[order], vectors[:, order]
        if np.linalg.det(vectors) < 0:
            vectors[:, 2] *= -1
        return values, vectors


@dataclass(frozen=True)
class Faces:
    """Per-face arrays every surface integral and sample needs, computed once per mesh.

    tri   : (f, 3, 3) corner coordinates
    cross : (f, 3) (b - a) x (c - a), twice the area times the unit normal
    area  : (f,) triangle areas
    """

    tri: np.ndarray
    cross: np.ndarray
    area: np.ndarray


def faces_of(mesh: Mesh) -> Faces:
    tri = mesh.vertices[mesh.faces]  # (f, 3, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # (f, 3)
    return Faces(tri, cross, 0.5 * np.sqrt(np.einsum("fi,fi->f", cross, cross)))


def moments(mesh: Mesh, faces: Faces | None = None) -> Moments:
    """Exact area moments of the triangles (the integral of x x^T over a triangle with corners a, b, c
    is A/12 (a a^T + b b^T + c c^T + s s^T) with s = a + b + c)."""
    f = faces or faces_of(mesh)
    tri, areas = f.tri, f.area
    total = float(areas.sum())
    centroid = areas @ (tri[:, 0] + tri[:, 1] + tri[:, 2]) / (3.0 * total)  # (3,)
    local = tri - centroid  # centring first keeps the sum exact for far-away meshes
    s = local[:, 0] + local[:, 1] + local[:, 2]  # (f, 3)
    corners = local.reshape(-1, 3)  # (3 f, 3)
    second = (corners * np.repeat(areas, 3)[:, None]).T @ corners + (s * areas[:, None]).T @ s
    return Moments(total, centroid, second / (12.0 * total))


def sample_surface(
    mesh: Mesh, n: int, seed: int = SAMPLE_SEED, faces: Faces | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n points uniformly by area on the surface, their unit face normals and faces: points (n, 3),
    normals (n, 3), face (n,) int."""
    f = faces or faces_of(mesh)
    tri, cross, areas = f.tri, f.cross, 2.0 * f.area
    rng = np.random.default_rng(seed)
    face = np.minimum(np.searchsorted(np.cumsum(areas), rng.random(n) * areas.sum()), len(areas) - 1)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1.0  # reflect into the triangle: uniform barycentric coordinates
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    t = tri[face]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    normals = cross[face] / np.maximum(areas[face], 1e-300)[:, None]
    return points, normals, face


def objects(mesh: Mesh, min_area_fraction: float = 0.02, max_objects: int = 64,
            min_faces: int = 0) -> list[Mesh]:
    """Split a mesh into its objects: connected components whose bounding boxes overlap are one object
    (a model's loose pieces, e.g. eyes in a head, stay together; the copies on a print plate part).

    Objects of fewer than `min_faces` faces are left out first (so that large flat trim cannot crowd the
    real parts out of the cap), then those smaller than `min_area_fraction` of the largest left; at most
    `max_objects`, largest first. A single-object mesh gives [mesh] itself.
    """
    labels = face_components(mesh.faces, mesh.n_vertices)  # (f,)
    n = int(labels.max()) + 1
    if n == 1 or n > MAX_COMPONENTS:  # thousands of pieces are a fragmented model, not a plate of parts
        return [mesh]
    tri = mesh.vertices[mesh.faces]
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    np.minimum.at(lo, labels, tri.min(axis=1))
    np.maximum.at(hi, labels, tri.max(axis=1))
    pad = 1e-3 * float(np.linalg.norm(mesh.vertices.max(0) - mesh.vertices.min(0)))
    overlap = np.all((lo[:, None] <= hi[None] + pad) & (lo[None] <= hi[:, None] + pad), axis=2)  # (n, n)
    import scipy.sparse as sp

    _, group = sp.csgraph.connected_components(sp.csr_matrix(overlap), directed=False)
    object_of_face = group[labels]
    if group.max() == 0:
        return [mesh]
    areas = np.bincount(object_of_face, weights=mesh.face_areas())
    areas[np.bincount(object_of_face) < min_faces] = 0.0  # trim: never an object, nor the yardstick
    if not areas.any():
        return []
    keep = [int(g) for g in np.argsort(-areas)
            if areas[g] > 0 and areas[g] >= min_area_fraction * areas.max()][:max_objects]
    return [submesh(mesh, object_of_face == g) for g in keep]


def submesh(mesh: Mesh, face_mask: np.ndarray) -> Mesh:
    """The faces where face_mask (f,) bool is set, with their vertices renumbered in order."""
    faces = mesh.faces[face_mask]
    used = np.unique(faces)
    remap = np.full(mesh.n_vertices, -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return Mesh(mesh.vertices[used], remap[faces])


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The closest point to p on triangle (a, b, c), row by row: all (n, 3) -> (n, 3).

    The Voronoi-region walk of Ericson, Real-Time Collision Detection, 5.1.5, vectorised: regions are
    assigned from the interior outwards so that each later (more specific) region overrides."""
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c

    def dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.einsum("ij,ij->i", x, y)

    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v, w = vb / denom, vc / denom
        out = a + ab * v[:, None] + ac * w[:, None]  # inside the face
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        edge_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
        out[edge_bc] = (b + (c - b) * t[:, None])[edge_bc]
        t = d2 / (d2 - d6)
        edge_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        out[edge_ac] = (a + ac * t[:, None])[edge_ac]
        t = d1 / (d1 - d3)
        edge_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        out[edge_ab] = (a + ab * t[:, None])[edge_ab]
    corner_c = (d6 >= 0) & (d5 <= d6)
    out[corner_c] = c[corner_c]
    corner_b = (d3 >= 0) & (d4 <= d3)
    out[corner_b] = b[corner_b]
    corner_a = (d1 <= 0) & (d2 <= 0)
    out[corner_a] = a[corner_a]
    bad = ~np.isfinite(out).all(axis=1)  # a degenerate triangle: its nearest corner will do
    if bad.any():
        corners = np.stack([a[bad], b[bad], c[bad]], axis=1)  # (k, 3, 3)
        pick = np.linalg.norm(corners - p[bad][:, None], axis=2).argmin(axis=1)
        out[bad] = corners[np.arange(len(pick)), pick]
    return out
