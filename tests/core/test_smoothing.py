"""Intrinsic smoothing (Taubin λ|μ with cotangent weights): its mathematics."""

from __future__ import annotations

import numpy as np
import trimesh

from app.core.mesh import Mesh
from app.core.resolution import smooth as uniform_taubin
from app.core.smoothing import cotangent_taubin, cotangent_weights


def _mesh(tm: trimesh.Trimesh) -> Mesh:
    return Mesh(np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64))


def _sphere(subdivisions: int = 3) -> Mesh:
    return _mesh(trimesh.creation.icosphere(subdivisions=subdivisions))


def test_zero_iterations_is_the_identity():
    sphere = _sphere()
    assert cotangent_taubin(sphere, 0) is sphere


def test_weights_average_the_neighbours():
    w, has = cotangent_weights(_sphere(2))
    assert has.all()
    assert np.allclose(np.asarray(w.sum(axis=1)).ravel(), 1.0) and w.data.min() > 0
    assert w.diagonal().max() == 0


def test_the_interior_of_a_flat_patch_does_not_move(random_rotation):
    # a planar Delaunay triangulation: every cotangent weight is positive, and a linear function is
    # its own cotangent average, so the filter moves no vertex whose neighbourhood is flat and complete
    rng = np.random.default_rng(0)
    xy = np.vstack([rng.random((200, 2)), [[0, 0], [1, 0], [0, 1], [1, 1]]])
    from scipy.spatial import Delaunay

    faces = Delaunay(xy).simplices.astype(np.int64)
    rot = random_rotation(7)  # a tilted plane, isometric to the Delaunay one (same angles)
    plane = Mesh(np.column_stack([xy, np.zeros(len(xy))]) @ rot.T, faces)
    out = cotangent_taubin(plane, 1)  # one λ|μ pair reaches two rings
    tm = trimesh.Trimesh(plane.vertices, plane.faces, process=False)
    edges = np.sort(tm.edges, axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    near = set(np.unique(unique[counts == 1]).tolist())  # boundary edges belong to one face
    for _ in range(2):  # the boundary (which moves: it has neighbours on one side) and its two rings
        near |= {int(j) for i in near for j in tm.vertex_neighbors[i]}
    far = np.setdiff1d(np.arange(plane.n_vertices), sorted(near))
    assert far.size > 50
    assert np.abs(out.vertices[far] - plane.vertices[far]).max() < 1e-12
    # every vertex, boundary included, stays on the plane: no motion off a flat surface
    many = cotangent_taubin(plane, 20).vertices
    assert np.abs(many @ rot[:, 2]).max() < 1e-12  # the plane's normal is the rotated z axis


def test_a_sphere_stays_a_sphere_of_almost_the_same_size():
    out = cotangent_taubin(_sphere(), 40)
    radii = np.linalg.norm(out.vertices, axis=1)
    assert radii.std() / radii.mean() < 2e-3
    assert 1.0 - radii.mean() < 0.01  # Taubin's μ step undoes the λ step's shrinkage: < 1 %


def test_commutes_with_rigid_motion_scale_and_vertex_order(random_rotation):
    rng = np.random.default_rng(1)
    base = _sphere(2)
    noisy = Mesh(base.vertices * [1.0, 0.7, 1.6] + 0.02 * rng.normal(size=base.vertices.shape), base.faces)
    out = cotangent_taubin(noisy, 20).vertices
    rot, shift, scale = random_rotation(4), np.array([3.0, -1.0, 5.0]), 7.5
    moved = cotangent_taubin(Mesh(scale * noisy.vertices @ rot.T + shift, noisy.faces), 20).vertices
    assert np.allclose(moved, scale * out @ rot.T + shift, atol=1e-9 * scale)
    perm = rng.permutation(noisy.n_vertices)
    shuffled = cotangent_taubin(Mesh(noisy.vertices[perm], np.argsort(perm)[noisy.faces]), 20)
    assert np.allclose(shuffled.vertices, out[perm], atol=1e-12)


def test_it_removes_vertex_noise():
    rng = np.random.default_rng(0)
    sphere = _sphere(4)  # 2562 vertices
    noisy = Mesh(sphere.vertices * (1.0 + 0.01 * rng.normal(size=(sphere.n_vertices, 1))), sphere.faces)

    def radial_spread(m: Mesh) -> float:
        r = np.linalg.norm(m.vertices, axis=1)
        return float(r.std() / r.mean())

    assert radial_spread(cotangent_taubin(noisy, 20)) < 0.4 * radial_spread(noisy)


def test_it_moves_an_irregular_triangulation_less_along_the_surface():
    # the same sphere, vertices slid along it at random: an irregular triangulation. Uniform weights
    # pull each vertex towards the centroid of its neighbours, regularising the sampling (motion
    # along the surface: a change of shape once the mesh is re-sampled); cotangent weights see a
    # sphere and move each vertex mostly along its normal
    rng = np.random.default_rng(3)
    sphere = _sphere(3)
    v = sphere.vertices + 0.02 * rng.normal(size=sphere.vertices.shape)
    mesh = Mesh(v / np.linalg.norm(v, axis=1, keepdims=True), sphere.faces)

    def slide(out: Mesh) -> float:
        """Mean angle between each vertex's direction before and after: motion along the sphere."""
        a = mesh.vertices
        b = out.vertices / np.linalg.norm(out.vertices, axis=1, keepdims=True)
        return float(np.arccos(np.clip((a * b).sum(axis=1), -1, 1)).mean())

    assert slide(cotangent_taubin(mesh, 40)) < 0.5 * slide(uniform_taubin(mesh, 40))
