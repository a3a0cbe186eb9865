"""Roughness at a mesh's own sampling (app.core.roughness) and the adaptive smoothing it drives."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.mesh import Mesh
from app.core.pipeline import DescribeParams, describe, smooth
from app.core.roughness import (
    NOISE_MIN_VERTICES,
    displacement_correlation,
    median_edge_length,
    roughness,
    smooth_until,
    vertex_normals,
)
from app.core.smoothing import taubin


def _sphere(subdivisions: int = 4) -> Mesh:
    tm = trimesh.creation.icosphere(subdivisions=subdivisions)
    return Mesh(np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64))


def _noisy(mesh: Mesh, sigma_edges: float, seed: int = 0) -> Mesh:
    """Each vertex moved along its normal by N(0, sigma) edge lengths."""
    rng = np.random.default_rng(seed)
    shift = rng.normal(size=(mesh.n_vertices, 1)) * sigma_edges * median_edge_length(mesh)
    return Mesh(mesh.vertices + vertex_normals(mesh) * shift, mesh.faces)


def test_a_flat_grid_has_no_roughness_whatever_its_triangulation():
    rng = np.random.default_rng(1)
    xy = np.vstack([rng.random((200, 2)), [[0, 0], [1, 0], [0, 1], [1, 1]]])
    from scipy.spatial import Delaunay

    faces = Delaunay(xy * [1.0, 4.0]).simplices.astype(np.int64)  # long, irregular triangles
    tilted = np.column_stack([xy, 0.3 * xy[:, 0] - 0.2 * xy[:, 1]])
    assert roughness(Mesh(tilted, faces)) < 1e-12


def test_a_smooth_sphere_reads_as_smooth_and_noise_as_rough():
    sphere = _sphere()
    clean = roughness(sphere)
    # κ h² / 4 is the same at every vertex of a sphere: δ is near-constant and W δ takes it away
    assert clean < 0.005
    levels = [roughness(_noisy(sphere, s)) for s in (0.02, 0.05, 0.2)]
    assert clean < levels[0] < levels[1] < levels[2]
    # independent normal noise of σ edges: |δ - Wδ| ~ σ (1 + 1/valence), its median ~ 0.7 σ
    assert 0.1 < levels[2] < 0.3


def test_roughness_ignores_rigid_motion_scale_and_vertex_order(random_rotation):
    mesh = _noisy(_sphere(3), 0.1, seed=3)
    rng = np.random.default_rng(5)
    perm = rng.permutation(mesh.n_vertices)
    inverse = np.argsort(perm)
    moved = Mesh(mesh.vertices[perm] @ random_rotation(2).T * 37.0 + [1.0, -4.0, 9.0], inverse[mesh.faces])
    assert roughness(moved) == pytest.approx(roughness(mesh), rel=1e-9)


def test_a_few_sharp_spikes_do_not_make_a_smooth_surface_rough():
    sphere = _sphere()
    spiky = sphere.vertices.copy()
    tips = np.random.default_rng(2).choice(sphere.n_vertices, 20, replace=False)  # 0.8 % of the vertices
    spiky[tips] *= 1.3
    assert roughness(Mesh(spiky, sphere.faces)) < 0.005
    assert roughness(_noisy(sphere, 0.05)) > 0.02  # where noise at every vertex is already rough


def test_smooth_until_stops_on_a_clean_mesh_and_smooths_a_noisy_one_to_its_target():
    sphere = _sphere()
    same, steps = smooth_until(sphere, target=0.02, max_steps=40)
    assert steps == 0 and same is sphere
    noisy = _noisy(sphere, 0.2)
    smoothed, steps = smooth_until(noisy, target=0.02, max_steps=40)
    assert 0 < steps < 40 and steps % 2 == 0
    assert roughness(smoothed) <= 0.02 < roughness(taubin(noisy, steps - 2, "capped-area"))
    # the same filter as taubin(): its first `steps` steps, not another one
    np.testing.assert_allclose(smoothed.vertices, taubin(noisy, steps, "capped-area").vertices, atol=1e-12)


def test_smooth_until_honours_its_ceiling():
    noisy = _noisy(_sphere(3), 0.5)
    assert smooth_until(noisy, target=1e-9, max_steps=6)[1] == 6
    assert smooth_until(noisy, target=1e-9, max_steps=7)[1] == 6  # whole λ|μ pairs only


def test_adaptive_smoothing_smooths_a_subdivided_mesh_fully_and_a_fine_one_by_its_noise():
    coarse = _sphere(1)  # 42 vertices: subdivided to reach the canonical resolution
    params = DescribeParams(smoothing=12, smoothing_target=10.0)  # a target every mesh here meets
    fine = _sphere(3)  # what subdividing it gives (642 vertices), as the describe's input or as its own
    np.testing.assert_allclose(smooth(fine, coarse.n_vertices, params).vertices,
                               taubin(fine, 12, "capped-area").vertices, atol=1e-12)
    # the same mesh given at its own resolution: nothing of ours to smooth, and it is smooth
    assert smooth(fine, fine.n_vertices, params) is fine
    noisy = _noisy(fine, 0.3)
    strict = DescribeParams(smoothing=12, smoothing_target=0.02)
    steps = smooth_until(noisy, 0.02, 12)[1]
    assert 0 < steps <= 12
    np.testing.assert_allclose(smooth(noisy, noisy.n_vertices, strict).vertices,
                               taubin(noisy, steps, "capped-area").vertices, atol=1e-12)


def test_fixed_smoothing_keeps_the_fingerprint_it_had_before_the_adaptive_option():
    assert "smoothing_target" not in DescribeParams(smoothing_target=0.0).fingerprint()
    assert "smoothing_target=0.04" in DescribeParams(smoothing_target=0.04).fingerprint()
    with pytest.raises(ValueError, match="smoothing_target"):
        DescribeParams(smoothing_target=-1.0)


def test_adaptive_describe_of_a_clean_fine_mesh_equals_the_unsmoothed_describe():
    sphere = _sphere(4)  # 2,562 vertices: decimated to ~1,000, smooth
    params = DescribeParams(k=20, m=16, smoothing_target=0.03)
    a = describe(sphere, params)
    b = describe(sphere, DescribeParams(k=20, m=16, smoothing=0))
    np.testing.assert_allclose(a.eigenvalues, b.eigenvalues, rtol=1e-9)


def _ellipsoid(subdivisions: int = 4) -> Mesh:
    sphere = _sphere(subdivisions)
    return Mesh(sphere.vertices * [1.0, 0.6, 0.3], sphere.faces)  # curvature varies over the surface


def test_displacement_correlation_is_positive_on_a_smooth_surface_and_negative_under_vertex_noise():
    """δ follows the curvature on a smooth surface (neighbours alike); white vertex noise puts each
    vertex's own offset into δ_i and, with the opposite sign, into its neighbours' (module docstring)."""
    ellipsoid = _ellipsoid()
    assert displacement_correlation(ellipsoid) > 0.5
    for sigma in (0.05, 0.3):
        assert displacement_correlation(_noisy(ellipsoid, sigma)) < 0.0


def test_displacement_correlation_ignores_scale_rigid_motion_and_vertex_order():
    mesh = _noisy(_ellipsoid(3), 0.1)
    base = displacement_correlation(mesh)
    rot = trimesh.transformations.random_rotation_matrix(np.random.default_rng(2).random(3))[:3, :3]
    moved = Mesh(mesh.vertices @ rot.T * 25.4 + [3.0, -1.0, 7.0], mesh.faces)
    perm = np.random.default_rng(3).permutation(mesh.n_vertices)
    inverse = np.argsort(perm)
    shuffled = Mesh(mesh.vertices[perm], inverse[mesh.faces])
    assert displacement_correlation(moved) == pytest.approx(base, abs=1e-9)
    assert displacement_correlation(shuffled) == pytest.approx(base, abs=1e-9)


def test_displacement_correlation_is_undefined_without_a_varying_displacement():
    assert np.isnan(displacement_correlation(Mesh(np.zeros((3, 3)), np.zeros((0, 3), np.int64))))
    square = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    flat_side = Mesh(square, np.array([[0, 1, 2], [1, 3, 2]]))
    assert np.isnan(displacement_correlation(flat_side))  # a plane: δ ≡ 0
    cube = trimesh.creation.box()  # 8 corners: nothing to tell noise from shape by
    assert np.isnan(displacement_correlation(Mesh(np.asarray(cube.vertices), np.asarray(cube.faces))))
    many = trimesh.creation.box().subdivide().subdivide().subdivide()  # 386 vertices, flat faces and creases
    assert len(many.vertices) >= NOISE_MIN_VERTICES
    assert np.isfinite(displacement_correlation(Mesh(np.asarray(many.vertices), np.asarray(many.faces))))
