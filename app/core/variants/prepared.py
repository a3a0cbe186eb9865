"""A mesh made ready for variant checks: computed once, compared many times (fingerprint, frame,
surface samples with a k-d tree, vertex tree, the set of its triangles, its objects)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from app.core.meshdata import Mesh
from app.core.variants.align import Frame, frame
from app.core.variants.fingerprint import fingerprint
from app.core.variants.onesided import mean_edge
from app.core.variants.surface import (
    Moments,
    closest_on_triangles,
    faces_of,
    moments,
    objects,
    sample_surface,
)

N_POINTS = 2048  # samples per surface for alignment and distances


@dataclass(eq=False)
class Prepared:
    mesh: Mesh

    @cached_property
    def _summary(self) -> tuple[Moments, np.ndarray, float]:
        """Moments, fingerprint and mean edge from one pass over the faces (their per-face arrays are
        not kept: a cached candidate keeps only what it is compared with)."""
        faces = faces_of(self.mesh)
        m = moments(self.mesh, faces)
        return m, fingerprint(self.mesh, faces, m), mean_edge(self.mesh, faces.tri)

    @cached_property
    def fingerprint(self) -> np.ndarray:
        """(17,) float32, see fingerprint.fingerprint."""
        return self._summary[1]

    @cached_property
    def frame(self) -> Frame:
        return frame(self.mesh, self._summary[0])

    @cached_property
    def diagonal(self) -> float:
        v = self.mesh.vertices
        return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))

    @cached_property
    def mean_edge(self) -> float:
        return self._summary[2]

    @cached_property
    def resolution(self) -> float:
        """Mean edge over the RMS radius: how coarse the mesh is, whatever its scale."""
        return self.mean_edge / self.frame.radius

    @cached_property
    def samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Surface points (N, 3), their unit normals (N, 3) and faces (N,) int."""
        return sample_surface(self.mesh, N_POINTS, seed=1)

    @cached_property
    def sample_tree(self) -> cKDTree:
        return cKDTree(self.samples[0])

    @cached_property
    def normalised_samples(self) -> np.ndarray:
        """(N, 3) samples in the principal frame, unit RMS radius."""
        return self.frame.normalise(self.samples[0])

    @cached_property
    def normalised_tree(self) -> cKDTree:
        return cKDTree(self.normalised_samples)

    @cached_property
    def used_vertices(self) -> np.ndarray:
        """(u, 3) the vertices some face uses, in index order (onesided.vertex_subset strides them)."""
        return self.mesh.vertices[np.unique(self.mesh.faces)]

    @cached_property
    def vertex_tree(self) -> cKDTree:
        return cKDTree(self.mesh.vertices)

    def distance_to(self, points: np.ndarray, k: int = 8) -> np.ndarray:
        """Distance (n,) from points (n, 3) to this surface: exact to the faces of the k nearest samples
        (the nearest face is among them unless it is far smaller than the sample spacing)."""
        _, idx = self.sample_tree.query(points, k=k, workers=1)  # (n, k)
        _, vertex = self.vertex_tree.query(points, workers=1)  # (n,): the faces around it catch thin parts
        candidates = np.sort(np.concatenate([self.samples[2][idx], self.vertex_faces[vertex]], axis=1))
        # each (point, face) pair once: near samples share faces, and a vertex's row repeats its faces
        first = np.ones(candidates.shape, dtype=bool)
        first[:, 1:] = candidates[:, 1:] != candidates[:, :-1]
        row, col = np.nonzero(first)  # row-major: each point's pairs together, every point has one
        flat = self.mesh.faces[candidates[row, col]]  # (pairs, 3)
        v, p = self.mesh.vertices, points[row]
        near = closest_on_triangles(p, v[flat[:, 0]], v[flat[:, 1]], v[flat[:, 2]])
        start = np.concatenate([[0], np.cumsum(first.sum(axis=1))[:-1]])  # (n,) each point's first pair
        return np.minimum.reduceat(np.linalg.norm(near - p, axis=1), start)

    @cached_property
    def vertex_faces(self) -> np.ndarray:
        """(n, 16) int: up to 16 faces around each vertex (repeated to fill the row)."""
        f = self.mesh.faces
        vertex = f.ravel()
        face = np.repeat(np.arange(len(f)), 3)
        order = np.argsort(vertex, kind="stable")
        vertex, face = vertex[order], face[order]
        start = np.searchsorted(vertex, np.arange(self.mesh.n_vertices))
        count = np.diff(np.append(start, len(vertex)))
        slot = np.minimum(np.arange(16)[None, :], np.maximum(count, 1)[:, None] - 1)  # (n, 8)
        return face[np.minimum(start[:, None] + slot, len(face) - 1)]

    def weld(self, tolerance: float) -> np.ndarray:
        """(n,) int label per vertex: vertices closer than `tolerance` (transitively) share one."""
        pairs = self.vertex_tree.query_pairs(tolerance, output_type="ndarray")  # (p, 2)
        if not len(pairs):
            return np.arange(self.mesh.n_vertices)
        n = self.mesh.n_vertices
        graph = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        return sp.csgraph.connected_components(graph, directed=False)[1]

    @cached_property
    def parts(self) -> list[Prepared]:
        """The objects of the mesh (surface.objects), each prepared; [self] for a single object."""
        found = objects(self.mesh)
        return [self] if len(found) == 1 else [Prepared(m) for m in found]


def face_keys(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    s = np.sort(faces, axis=1).astype(np.int64)
    n = np.int64(n_vertices)
    return np.sort((s[:, 0] * n + s[:, 1]) * n + s[:, 2])
