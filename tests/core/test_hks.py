"""HKS (eqs. 1-4): time scales, the heat kernel on a known spectrum, and invariances."""

from __future__ import annotations

import numpy as np

from app.core import hks
from app.core.laplacian import cotangent_laplacian
from app.core.mesh import Mesh
from app.core.resolution import normalize_scale
from app.core.spectrum import Spectrum, smallest_eigenpairs


def test_time_scales_span_eq_1_2_and_skip_the_zero_eigenvalues():
    lam = np.array([0.0, 0.0, 2.0, 3.0, 50.0])  # two components: λ2 is the first non-zero one
    t = hks.time_scales(lam, m=100)  # the default: the paper's
    assert np.isclose(t[0], 4 * np.log(10) / 50.0) and np.isclose(t[-1], 4 * np.log(10) / 2.0)
    assert np.allclose(np.diff(np.log(t)), np.log(t[1] / t[0]))  # log-spaced


def test_weyl_time_range_takes_lambda_k_from_the_area():
    lam = np.array([0.0, 2.0, 3.0, 50.0])
    t = hks.time_scales(lam, m=10, time_range="weyl")  # Weyl's λ_k = 4πk / A, unit area
    assert np.isclose(t[0], 4 * np.log(10) / (4 * np.pi * 4)) and np.isclose(t[-1], 4 * np.log(10) / 2.0)
    # λ_k ~ 1/A: on 4 times the area, t_min is 4 times larger
    assert np.isclose(hks.time_scales(lam, m=10, time_range="weyl", area=4.0)[0], 4 * t[0])
    import pytest

    with pytest.raises(ValueError, match="time_range"):
        hks.time_scales(lam, time_range="paper")


def _unit_sphere_spectrum(vertices: np.ndarray, faces: np.ndarray, k: int) -> np.ndarray:
    work = normalize_scale(Mesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int64)))
    L, M = cotangent_laplacian(work.vertices, work.faces)
    return smallest_eigenpairs(L, M, k=k).eigenvalues


def test_weyl_time_range_does_not_depend_on_the_triangulation():
    import trimesh

    # the same unit-area sphere, a regular icosphere and an irregular UV sphere, ~650 vertices each
    ico = trimesh.creation.icosphere(subdivisions=3)
    uv = trimesh.creation.uv_sphere(count=[24, 28])
    a = _unit_sphere_spectrum(ico.vertices, ico.faces, 200)
    b = _unit_sphere_spectrum(uv.vertices, uv.faces, 200)
    weyl = [hks.time_scales(e, 20, time_range="weyl") for e in (a, b)]
    paper = [hks.time_scales(e, 20, time_range="spectrum") for e in (a, b)]
    # λ_2 (= 2/r² = 8π on the unit-area sphere) converges fast: t_max agrees within 1 % either way
    assert np.isclose(a[1], 8 * np.pi, rtol=0.01) and np.isclose(b[1], 8 * np.pi, rtol=0.01)
    # the top of the computed spectrum does not: the paper's t_min moves with the mesh, Weyl's does not
    assert abs(paper[0][0] / paper[1][0] - 1) > 0.03
    assert np.isclose(weyl[0][0], weyl[1][0], rtol=1e-12)


def test_heat_kernel_matches_formula_on_a_hand_made_spectrum():
    phi = np.array([[0.5, 1.0], [0.5, -1.0]])
    spec = Spectrum(np.array([0.0, 2.0]), phi)
    k = hks.heat_kernel_signature(spec, np.array([0.0, 1.0]))
    expected = np.array([[0.25 + 1.0, 0.25 + np.exp(-2.0)], [0.25 + 1.0, 0.25 + np.exp(-2.0)]])
    assert np.allclose(k, expected)


def test_normalisation_gives_unit_vectors():
    h = hks.normalize(np.random.default_rng(0).random((7, 100)))
    assert np.allclose(np.linalg.norm(h, axis=1), 1.0)


def _hks_of(mesh: Mesh) -> np.ndarray:
    work = normalize_scale(mesh)
    L, M = cotangent_laplacian(work.vertices, work.faces)
    spec = smallest_eigenpairs(L, M, k=60)
    return hks.normalize(hks.heat_kernel_signature(spec, hks.time_scales(spec.eigenvalues, 100)))


def test_hks_is_unchanged_by_rigid_motion_scale_and_vertex_order(shrec_mesh, random_rotation):
    base = _hks_of(shrec_mesh)
    moved = Mesh(3.7 * shrec_mesh.vertices @ random_rotation(1).T + [10.0, -4.0, 2.5], shrec_mesh.faces)
    assert np.allclose(_hks_of(moved), base, atol=1e-6)
    perm = np.random.default_rng(2).permutation(shrec_mesh.n_vertices)
    inverse = np.argsort(perm)
    permuted = Mesh(shrec_mesh.vertices[perm], inverse[shrec_mesh.faces])
    assert np.allclose(_hks_of(permuted)[inverse], base, atol=1e-6)


def test_hks_on_the_sphere_is_constant(ellipsoid_mesh):
    import trimesh

    tm = trimesh.creation.icosphere(subdivisions=3)
    h = _hks_of(Mesh(np.asarray(tm.vertices), np.asarray(tm.faces)))
    # the icosphere is almost homogeneous: every vertex has nearly the same signature
    assert np.abs(h - h.mean(axis=0)).max() < 0.005
    # the ellipsoid is not: its poles differ from its waist
    c = _hks_of(ellipsoid_mesh)
    assert np.abs(c - c.mean(axis=0)).max() > 0.01
