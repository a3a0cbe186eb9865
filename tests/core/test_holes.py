"""Closing small holes: the loops found, the caps watertight and wound with their neighbours, large
loops left open, punctures welded, and the heat kernel near a closed hole back to the whole surface's."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core import hks
from app.core.holes import boundary_loops, fill_holes
from app.core.laplacian import laplacian
from app.core.mesh import Mesh
from app.core.spectrum import smallest_eigenpairs


def _sphere(subdivisions: int = 3) -> Mesh:
    tm = trimesh.creation.icosphere(subdivisions=subdivisions)
    return Mesh(np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64))


def _without_cap(mesh: Mesh, direction: np.ndarray, cos_angle: float) -> Mesh:
    """The faces whose centroid is within the cone around `direction` removed (one round hole)."""
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    unit = centroids / np.linalg.norm(centroids, axis=1, keepdims=True)
    return Mesh(mesh.vertices, mesh.faces[unit @ direction < cos_angle])


def _directed_edges_pair_up(faces: np.ndarray) -> bool:
    """Watertight and consistently wound: each directed edge once, and its reverse once."""
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    as_set = {tuple(e) for e in directed}
    return len(as_set) == len(directed) and all((b, a) in as_set for a, b in directed)


def _compact(mesh: Mesh) -> Mesh:
    used, inverse = np.unique(mesh.faces, return_inverse=True)
    return Mesh(mesh.vertices[used], inverse.reshape(-1, 3))


UP = np.array([0.0, 0.0, 1.0])


def test_a_closed_surface_has_no_loops_and_is_returned_as_it_is():
    sphere = _sphere()
    assert boundary_loops(sphere.faces, sphere.n_vertices) == []
    out, closed = fill_holes(sphere, 0.05)
    assert closed == 0 and out is sphere


def test_one_hole_is_one_loop_in_the_winding_order_of_its_faces():
    holed = _compact(_without_cap(_sphere(), UP, 0.95))
    loops = boundary_loops(holed.faces, holed.n_vertices)
    assert len(loops) == 1
    loop = loops[0]
    # every rim vertex is on the loop once, and consecutive ones are an edge of a face, a -> b there
    directed = {tuple(e) for e in holed.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)}
    assert len(set(loop.tolist())) == len(loop) >= 5
    rim = zip(loop, np.roll(loop, -1), strict=True)
    assert all((a, b) in directed and (b, a) not in directed for a, b in rim)
    # the rim is the circle the cap was cut along
    rim_z = holed.vertices[loop, 2]
    assert rim_z.min() > 0.9 and np.ptp(rim_z) < 0.08


def test_a_small_hole_is_closed_watertight_with_one_vertex_at_its_centre():
    holed = _compact(_without_cap(_sphere(), UP, 0.95))
    out, closed = fill_holes(holed, 0.05)
    assert closed == 1
    assert out.n_vertices == holed.n_vertices + 1
    assert _directed_edges_pair_up(out.faces)
    centre = out.vertices[-1]
    assert abs(centre[0]) < 1e-9 and abs(centre[1]) < 1e-9 and 0.9 < centre[2] < 1.0  # on the axis
    # a flat fan over the zig-zag rim: about the area of the faces removed
    removed = _sphere().face_areas().sum() - holed.face_areas().sum()
    added = out.face_areas().sum() - holed.face_areas().sum()
    assert 0.8 * removed < added < 1.2 * removed
    # wound with the faces beside it: the cap's normals point out of the sphere, as the others do
    normals = np.cross(*(out.vertices[out.faces[-3:, i]] - out.vertices[out.faces[-3:, 0]] for i in (1, 2)))
    assert np.all(normals[:, 2] > 0)


def test_a_hole_larger_than_the_budget_stays_open():
    holed = _compact(_without_cap(_sphere(), UP, 0.5))  # a quarter of the sphere is gone
    cap_fraction = np.pi * (1 - 0.5**2) / holed.face_areas().sum()  # the disc under the cut, roughly
    assert cap_fraction > 0.2
    out, closed = fill_holes(holed, 0.05)
    assert closed == 0 and out is holed
    out, closed = fill_holes(holed, 0.5)
    assert closed == 1 and _directed_edges_pair_up(out.faces)


def test_only_the_small_one_of_two_holes_is_closed():
    sphere = _sphere()
    holed = _without_cap(_without_cap(sphere, UP, 0.97), -UP, 0.6)
    holed = _compact(holed)
    assert len(boundary_loops(holed.faces, holed.n_vertices)) == 2
    out, closed = fill_holes(holed, 0.05)
    assert closed == 1
    left = boundary_loops(out.faces, out.n_vertices)
    assert len(left) == 1 and np.all(out.vertices[left[0], 2] < 0)  # the bottom one stays


def test_zero_leaves_every_hole_open():
    holed = _compact(_without_cap(_sphere(), UP, 0.95))
    out, closed = fill_holes(holed, 0.0)
    assert closed == 0 and out is holed


def test_a_puncture_is_left_open_rather_than_given_a_vertex_without_area():
    """A face collapsed to a point (three distinct vertices ~1e-8 apart, the face itself removed): a
    cap there would give a vertex of no area, which the eigen-solve refuses."""
    sphere = _sphere()
    v, f = sphere.vertices.copy(), sphere.faces.copy()
    a, b, c = f[0]
    v[b] = v[a] + 1e-8
    v[c] = v[a] - 1e-8
    punctured = Mesh(v, f[1:])
    assert len(boundary_loops(punctured.faces, punctured.n_vertices)) == 1
    out, closed = fill_holes(punctured, 0.05)
    assert closed == 0 and out is punctured
    # beside a real hole, the real hole is still closed
    holed = _compact(_without_cap(punctured, -UP, 0.95))
    out, closed = fill_holes(holed, 0.05)
    assert closed == 1
    _, mass = laplacian(out.vertices, out.faces, "intrinsic")
    assert mass.diagonal().min() > 0


def test_a_pinched_boundary_is_left_open():
    """Two holes that share one vertex: the rim visits it twice, its order is not defined."""
    sphere = _sphere(2)
    v, f = sphere.vertices, sphere.faces
    shared = 0
    ring = np.flatnonzero(np.any(f == shared, axis=1))  # the faces around vertex 0
    # remove two faces around the vertex that touch it only there (non-adjacent in its fan)
    removed = [ring[0]]
    for r in ring[1:]:
        if len(set(f[r]) & set(f[ring[0]])) == 1:
            removed.append(r)
            break
    pinched = Mesh(v, np.delete(f, removed, axis=0))
    assert boundary_loops(pinched.faces, pinched.n_vertices) == []
    out, closed = fill_holes(pinched, 0.05)
    assert closed == 0 and out is pinched


def test_closing_commutes_with_a_similarity_transform():
    holed = _compact(_without_cap(_sphere(), UP, 0.95))
    rot = trimesh.transformations.rotation_matrix(0.7, [1, 2, 3])[:3, :3]
    moved = Mesh(holed.vertices @ rot.T * 3.5 + [1.0, -2.0, 0.5], holed.faces)
    a, _ = fill_holes(holed, 0.05)
    b, _ = fill_holes(moved, 0.05)
    assert np.array_equal(a.faces, b.faces)
    assert np.allclose(a.vertices @ rot.T * 3.5 + [1.0, -2.0, 0.5], b.vertices)


@pytest.mark.slow  # large eigenproblems of three spheres per case
@pytest.mark.parametrize("times_index", [20, 40])
def test_the_heat_kernel_by_a_closed_hole_is_the_whole_spheres_again(times_index: int):
    """On a sphere K_t(x, x) is the same at every point. A hole makes its rim a boundary (Neumann:
    heat is reflected, K_t rises there); the closed hole lets heat across again."""
    sphere = _sphere(3)
    holed = _compact(_without_cap(sphere, UP, 0.97))
    closed, _ = fill_holes(holed, 0.05)

    def kernel(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
        stiffness, mass = laplacian(mesh.vertices, mesh.faces, "intrinsic")
        spec = smallest_eigenpairs(stiffness, mass, 120)
        t = hks.time_scales(smallest_eigenpairs(*laplacian(sphere.vertices, sphere.faces, "intrinsic"),
                                                120).eigenvalues, 100)[times_index]
        return hks.heat_kernel_signature(spec, np.array([t]))[:, 0], mesh.vertices

    k_sphere, _ = kernel(sphere)
    k_holed, v_holed = kernel(holed)
    k_closed, v_closed = kernel(closed)
    near = lambda v: v[:, 2] > 0.8  # noqa: E731 -- the band around the hole
    reference = float(np.median(k_sphere))
    open_error = np.abs(k_holed[near(v_holed)] / reference - 1).max()
    closed_error = np.abs(k_closed[near(v_closed)] / reference - 1).max()
    assert open_error > 0.1
    assert closed_error < open_error / 3


def _grid(n: int) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """A flat n x n grid of unit squares, two triangles each: vertices, faces, the cell of each face."""
    xs = np.arange(n + 1.0)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    v = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    idx = np.arange(len(v)).reshape(n + 1, n + 1)
    faces, cells = [], []
    for i in range(n):
        for j in range(n):
            a, b, c, d = idx[i, j], idx[i + 1, j], idx[i + 1, j + 1], idx[i, j + 1]
            faces += [[a, b, c], [a, c, d]]
            cells += [(i, j), (i, j)]
    return v, np.asarray(faces, np.int64), cells


def test_a_rim_whose_centroid_lies_on_one_of_its_edges_is_left_open():
    """A non-convex hole in a flat grid whose rim centroid falls on the line of a rim edge: its fan
    would hold a triangle of no area (a cotangent weight of ~1e307), so the hole is not closed."""
    v, f, cells = _grid(30)
    gone = {(13, 14), (13, 15), (14, 14), (15, 14), (15, 15), (16, 14), (16, 15)}
    sheet = _compact(Mesh(v, f[[c not in gone for c in cells]]))
    assert len(boundary_loops(sheet.faces, sheet.n_vertices)) == 2  # the outline and the hole
    out, closed = fill_holes(sheet, 0.05)
    assert closed == 0 and out is sheet
    # a square hole in the same sheet has a fan of 8 equal triangles, and is closed
    square = {(13, 13), (13, 14), (14, 13), (14, 14)}
    sheet = _compact(Mesh(v, f[[c not in square for c in cells]]))
    out, closed = fill_holes(sheet, 0.05)
    assert closed == 1 and out.face_areas().min() > 0.4
    assert len(boundary_loops(out.faces, out.n_vertices)) == 1  # the outline stays


def test_a_small_open_part_beside_a_big_closed_one_keeps_its_outline():
    """The budget is the loop's own piece's area: a sheet of 2 % of the whole is not folded shut."""
    sphere = _sphere()
    v, f, _ = _grid(4)
    side = np.sqrt(0.02 * sphere.face_areas().sum())
    sheet_v = v * (side / 4) + [3.0, 0.0, 0.0]
    both = Mesh(np.vstack([sphere.vertices, sheet_v]), np.vstack([sphere.faces, f + sphere.n_vertices]))
    assert len(boundary_loops(both.faces, both.n_vertices)) == 1
    out, closed = fill_holes(both, 0.05)
    assert closed == 0 and out is both
