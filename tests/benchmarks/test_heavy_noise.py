"""benchmarks/heavy_noise.py: the fold share and the watertight test it reads inputs with."""

from __future__ import annotations

import math

import numpy as np
import trimesh

from app.core.meshdata import Mesh
from benchmarks.heavy_noise import fold_share, watertight


def _sphere() -> Mesh:
    s = trimesh.creation.icosphere(3)  # 642 vertices
    return Mesh(np.asarray(s.vertices, float), np.asarray(s.faces))


def test_a_smooth_closed_surface_has_no_fold_and_is_watertight():
    mesh = _sphere()
    assert fold_share(mesh) == 0.0 and watertight(mesh)
    assert not watertight(Mesh(mesh.vertices, mesh.faces[1:]))  # one face less: three edges on one face


def test_noise_of_a_few_edges_folds_about_half_the_edges_and_light_noise_none():
    mesh = _sphere()
    first, second = mesh.vertices[mesh.faces[:, 0]], mesh.vertices[mesh.faces[:, 1]]
    edge = float(np.linalg.norm(first - second, axis=1).mean())
    rng = np.random.default_rng(0)
    normal = mesh.vertices / np.linalg.norm(mesh.vertices, axis=1, keepdims=True)
    # isotropic noise of a few edges scrambles the triangles: about half the edges fold (0.51 at 3 to 30
    # edges, as heavy noise reads on real columns: docs/results.md)
    heavy = Mesh(mesh.vertices + rng.normal(0, 3 * edge, mesh.vertices.shape), mesh.faces)
    light = Mesh(mesh.vertices + normal * rng.normal(0, 0.01 * edge, (len(normal), 1)), mesh.faces)
    assert 0.4 < fold_share(heavy) < 0.6 and fold_share(light) == 0.0
    assert watertight(heavy)  # the noise moves vertices, it opens nothing


def test_a_folded_pair_of_triangles_counts_as_a_fold():
    """Two consistently wound triangles on one edge, the second turned back over the first: their
    normals are opposite."""
    grid = _sphere()  # 100 vertices or more are needed for a figure: add the pair to a sphere far away
    v = np.vstack([grid.vertices, [[10, 0, 0], [11, 0, 0], [10, 1, 0], [10.5, 0.9, 0.01]]])
    n = len(grid.vertices)
    # the shared edge runs n -> n+1 in the first and n+1 -> n in the second, whose third corner lies on
    # the first's side: the surface folds back on itself
    f = np.vstack([grid.faces, [[n, n + 1, n + 2], [n + 1, n, n + 3]]])
    edges = 3 * len(grid.faces) // 2 + 1  # the sphere's interior edges and the pair's shared one
    assert math.isclose(fold_share(Mesh(v, f)), 1 / edges)


def test_too_few_vertices_are_not_measured():
    tet = trimesh.creation.icosahedron()
    assert math.isnan(fold_share(Mesh(np.asarray(tet.vertices, float), np.asarray(tet.faces))))
