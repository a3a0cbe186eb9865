"""Taubin λ|μ smoothing (app.core.smoothing): its mathematics, for each weighting."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import Delaunay

from app.core.mesh import Mesh
from app.core.smoothing import AVERAGED, LAMBDA, MU, WEIGHTS, averaging_operator, taubin


def _mesh(tm: trimesh.Trimesh) -> Mesh:
    return Mesh(np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64))


def _sphere(subdivisions: int = 3) -> Mesh:
    return _mesh(trimesh.creation.icosphere(subdivisions=subdivisions))


def _skewed_plane(rotation: np.ndarray) -> tuple[Mesh, np.ndarray]:
    """A tilted unit square whose triangulation is not Delaunay (the Delaunay triangulation of a copy
    stretched 6x along y: long triangles, 440 negative extrinsic cotangent weights), and its vertices
    in the middle (0.3 < x, y < 0.7), far from the boundary, which moves."""
    rng = np.random.default_rng(0)
    xy = np.vstack([rng.random((300, 2)), [[0, 0], [1, 0], [0, 1], [1, 1]]])
    faces = Delaunay(xy * [1.0, 6.0]).simplices.astype(np.int64)
    plane = Mesh(np.column_stack([xy, np.zeros(len(xy))]) @ rotation.T, faces)
    return plane, np.where((np.abs(xy - 0.5) < 0.2).all(axis=1))[0]


@pytest.mark.parametrize("weights", WEIGHTS)
def test_zero_steps_is_the_identity(weights):
    sphere = _sphere()
    assert taubin(sphere, 0, weights) is sphere


def test_an_unknown_weighting_is_refused():
    with pytest.raises(ValueError, match="intrinsic, cotangent, area, capped-area, uniform"):
        taubin(_sphere(1), 2, "laplace")
    with pytest.raises(ValueError, match="one of intrinsic, cotangent, area, capped-area, not"):
        averaging_operator(_sphere(1), "uniform")


@pytest.mark.parametrize("weights", AVERAGED)
def test_weights_average_the_neighbours(weights):
    w, has = averaging_operator(_sphere(2), weights)
    assert has.all()
    assert np.allclose(np.asarray(w.sum(axis=1)).ravel(), 1.0) and w.data.min() > 0
    assert w.diagonal().max() == 0


@pytest.mark.parametrize("weights", AVERAGED)
def test_steps_alternate_lambda_and_mu(weights):
    # `steps` counts single steps (trimesh's convention): 1 is a λ step, 2 a λ step then a μ step
    rng = np.random.default_rng(2)
    base = _sphere(2)
    mesh = Mesh(base.vertices + 0.05 * rng.normal(size=base.vertices.shape), base.faces)
    w, _ = averaging_operator(mesh, weights)
    x = mesh.vertices
    one = x + LAMBDA * (w @ x - x)
    two = one + MU * (w @ one - one)
    assert np.allclose(taubin(mesh, 1, weights).vertices, one, atol=1e-14)
    assert np.allclose(taubin(mesh, 2, weights).vertices, two, atol=1e-14)


def test_uniform_steps_are_trimesh_filter_taubin():
    rng = np.random.default_rng(5)
    base = _sphere(2)
    mesh = Mesh(base.vertices + 0.05 * rng.normal(size=base.vertices.shape), base.faces)
    tm = trimesh.Trimesh(mesh.vertices.copy(), mesh.faces, process=False)
    trimesh.smoothing.filter_taubin(tm, lamb=0.5, nu=0.53, iterations=7)
    np.testing.assert_array_equal(taubin(mesh, 7, "uniform").vertices, tm.vertices)


def _grid(size: int) -> Mesh:
    """A flat size x size grid of unit squares, each cut by the same diagonal: every face has area ½
    and every interior vertex six neighbours."""
    ij = np.array([(i, j) for i in range(size + 1) for j in range(size + 1)], dtype=np.float64)
    idx = np.arange((size + 1) ** 2).reshape(size + 1, size + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel()
    faces = np.vstack([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    return Mesh(np.column_stack([ij, np.zeros(len(ij))]), faces.astype(np.int64))


@pytest.mark.parametrize("weights", ["area", "capped-area"])
def test_area_weights_are_uniform_where_the_surface_is_sampled_evenly(weights):
    # every face the same area, every interior vertex the same star: nothing for the areas to weigh,
    # so the rows of vertices two rings from the boundary are the uniform average exactly
    size = 6
    grid = _grid(size)
    w, _ = averaging_operator(grid, weights)
    xy = grid.vertices[:, :2]
    deep = np.where(((xy >= 2) & (xy <= size - 2)).all(axis=1))[0]
    assert deep.size == 9
    for i in deep:
        row = w.getrow(i)
        assert row.nnz == 6 and np.allclose(row.data, 1 / 6, atol=1e-15)


def test_the_area_average_does_not_follow_the_count_of_neighbours():
    # a flat fan whose rim has 12 vertices on one half-circle and 3 on the other: the uniform average
    # of the rim is pulled to the crowded side (by 0.35 of the radius); the average by the surface the
    # neighbours stand for stays near the centre, where the star's own surface is centred
    angles = np.concatenate([np.linspace(0, np.pi, 12, endpoint=False), np.pi + np.pi * np.arange(1, 4) / 4])
    rim = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(15)])
    fan = Mesh(np.vstack([[0.0, 0.0, 0.0], rim]),
               np.array([[0, 1 + j, 1 + (j + 1) % 15] for j in range(15)], dtype=np.int64))
    w, _ = averaging_operator(fan, "area")
    uniform = np.linalg.norm(rim.mean(axis=0))
    weighted = np.linalg.norm(w.getrow(0) @ fan.vertices)
    assert uniform > 0.3
    assert weighted < 0.2 * uniform  # 0.053 against 0.352


def _fan(angles: np.ndarray, radii: np.ndarray | None = None) -> Mesh:
    """A flat fan: vertex 0 at the origin, rim vertex 1 + j at angles[j] (radius radii[j], 1 by
    default), face j between rim vertices j and j + 1 (cyclically)."""
    r = np.ones(len(angles)) if radii is None else radii
    rim = np.column_stack([r * np.cos(angles), r * np.sin(angles), np.zeros(len(angles))])
    n = len(angles)
    return Mesh(np.vstack([[0.0, 0.0, 0.0], rim]),
                np.array([[0, 1 + j, 1 + (j + 1) % n] for j in range(n)], dtype=np.int64))


def test_capped_area_weights_still_discount_a_crowded_side():
    # 4 rim vertices 0.1 rad apart, 7 more spread over the rest of the circle: the three small faces
    # are below the median face, so the cap does not touch them, and the average stays near the centre
    # where the uniform one is pulled to the cluster
    angles = np.concatenate([0.1 * np.arange(4), np.linspace(0.3, 2 * np.pi, 9)[1:-1]])
    fan = _fan(angles)
    uniform = np.linalg.norm(fan.vertices[1:].mean(axis=0))
    capped = np.linalg.norm(averaging_operator(fan, "capped-area")[0].getrow(0) @ fan.vertices)
    area = np.linalg.norm(averaging_operator(fan, "area")[0].getrow(0) @ fan.vertices)
    assert uniform > 0.2
    assert capped == pytest.approx(area, abs=1e-12)  # no face is above the median
    assert capped < 0.25 * uniform


def test_capped_area_weights_give_a_large_face_no_more_than_a_usual_one():
    # a regular hexagonal fan with one rim vertex pulled out to 5x the radius: its two faces are 5x
    # the others, above the median. Area weights let that neighbour pull with 10/28 of the row; capped
    # at the median, every face counts as the usual one and the row is the uniform 1/6
    fan = _fan(np.pi / 3 * np.arange(6), np.array([5.0, 1, 1, 1, 1, 1]))
    capped = averaging_operator(fan, "capped-area")[0].getrow(0)
    area = averaging_operator(fan, "area")[0].getrow(0)
    assert np.allclose(capped.toarray().ravel()[1:], 1 / 6, atol=1e-15)
    assert area[0, 1] == pytest.approx(10 / 28)


def test_the_middle_of_a_flat_patch_stays_put_only_with_intrinsic_weights(random_rotation):
    # A linear function is its own average under the cotangent weights of any planar triangulation in
    # which they are all ≥ 0: the intrinsic Delaunay one (flips keep a plane a plane). The extrinsic
    # weights of a non-Delaunay triangulation are clipped (the clipped average is not linear-exact),
    # and uniform weights slide each vertex towards its neighbours' centroid: both move the middle
    rot = random_rotation(7)
    plane, middle = _skewed_plane(rot)
    assert middle.size > 40
    edge = 0.11  # the mean edge length of this triangulation

    def motion(weights: str, steps: int) -> float:
        return float(np.abs(taubin(plane, steps, weights).vertices[middle] - plane.vertices[middle]).max())

    for steps in (1, 2, 10):
        assert motion("intrinsic", steps) < 1e-3 * edge  # robust-laplacian's mollification: ~1e-6
        assert motion("cotangent", steps) > 0.05 * edge
        assert motion("uniform", steps) > 0.2 * edge
        assert motion("area", steps) > 0.05 * edge  # it slides too
        assert motion("capped-area", steps) > 0.05 * edge
    for weights in WEIGHTS:  # and nothing leaves the plane, the boundary included
        assert np.abs(taubin(plane, 10, weights).vertices @ rot[:, 2]).max() < 1e-12


@pytest.mark.parametrize("weights", WEIGHTS)
def test_a_sphere_stays_a_sphere_of_almost_the_same_size(weights):
    out = taubin(_sphere(), 40, weights)
    radii = np.linalg.norm(out.vertices, axis=1)
    assert radii.std() / radii.mean() < 2e-3
    assert 1.0 - radii.mean() < 0.01  # Taubin's μ step undoes the λ step's shrinkage: < 1 %


@pytest.mark.parametrize("weights", WEIGHTS)
def test_commutes_with_rigid_motion_scale_and_vertex_order(random_rotation, weights):
    rng = np.random.default_rng(1)
    base = _sphere(2)
    noisy = Mesh(base.vertices * [1.0, 0.7, 1.6] + 0.02 * rng.normal(size=base.vertices.shape), base.faces)
    out = taubin(noisy, 20, weights).vertices
    rot, shift, scale = random_rotation(4), np.array([3.0, -1.0, 5.0]), 7.5
    moved = taubin(Mesh(scale * noisy.vertices @ rot.T + shift, noisy.faces), 20, weights).vertices
    assert np.allclose(moved, scale * out @ rot.T + shift, atol=1e-8 * scale)
    perm = rng.permutation(noisy.n_vertices)
    shuffled = taubin(Mesh(noisy.vertices[perm], np.argsort(perm)[noisy.faces]), 20, weights)
    assert np.allclose(shuffled.vertices, out[perm], atol=1e-10)


@pytest.mark.parametrize("weights", WEIGHTS)
def test_it_removes_vertex_noise(weights):
    rng = np.random.default_rng(0)
    sphere = _sphere(4)  # 2562 vertices
    noisy = Mesh(sphere.vertices * (1.0 + 0.01 * rng.normal(size=(sphere.n_vertices, 1))), sphere.faces)

    def radial_spread(m: Mesh) -> float:
        r = np.linalg.norm(m.vertices, axis=1)
        return float(r.std() / r.mean())

    assert radial_spread(taubin(noisy, 20, weights)) < 0.5 * radial_spread(noisy)


@pytest.mark.parametrize("weights", ["intrinsic", "cotangent"])
def test_it_moves_an_irregular_triangulation_less_along_the_surface(weights):
    # the same sphere, vertices slid along it at random: an irregular triangulation. Uniform weights
    # pull each vertex towards the centroid of its neighbours, regularising the sampling (motion
    # along the surface: a change of shape once the mesh is re-sampled); the surface's weights see a
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

    assert slide(taubin(mesh, 40, weights)) < 0.5 * slide(taubin(mesh, 40, "uniform"))


# Taubin with the surface's weights on a hand-solvable mesh: one
# equilateral triangle and a vertex in no face. The triangle's weights are equal, so W averages the
# other two vertices and each step s scales the offsets from the centroid by 1 - 1.5 s; the lone vertex
# has no neighbour and stays.


TRIANGLE = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, np.sqrt(3.0), 0.0]])
LONE = np.array([[5.0, 4.0, 3.0]])


def _triangle_and_lone_vertex() -> Mesh:
    return Mesh(np.vstack([TRIANGLE, LONE]), np.array([[0, 1, 2]], np.int64))


@pytest.mark.parametrize("weights", ["intrinsic", "cotangent"])
def test_weights_of_a_lone_triangle_and_a_vertex_in_no_face(weights):
    # every cotangent weight is cot 60° / 2 < 1 per row
    w, has = averaging_operator(_triangle_and_lone_vertex(), weights)
    assert has.tolist() == [True, True, True, False]
    expected = np.zeros((4, 4))
    expected[:3, :3] = 0.5
    np.fill_diagonal(expected, 0.0)
    assert np.allclose(w.toarray(), expected, atol=1e-12)


@pytest.mark.parametrize("weights", ["intrinsic", "cotangent"])
def test_one_pair_of_steps_shrinks_the_triangle_about_its_centroid_and_leaves_the_lone_vertex(weights):
    mesh = _triangle_and_lone_vertex()
    out = taubin(mesh, 2, weights)  # λ = 0.5, then μ = -0.53
    centroid = TRIANGLE.mean(axis=0)
    factor = (1 - 1.5 * 0.5) * (1 - 1.5 * -0.53)
    assert np.allclose(out.vertices[:3], centroid + factor * (TRIANGLE - centroid), atol=1e-10)
    assert np.array_equal(out.vertices[3:], LONE)
    assert np.array_equal(out.faces, mesh.faces)
    one = taubin(mesh, 1, weights).vertices  # a single λ step
    assert np.allclose(one[:3], centroid + (1 - 1.5 * 0.5) * (TRIANGLE - centroid), atol=1e-10)
    four = taubin(mesh, 4, weights).vertices  # W from the input geometry: the same factor again
    assert np.allclose(four[:3], centroid + factor**2 * (TRIANGLE - centroid), atol=1e-10)
