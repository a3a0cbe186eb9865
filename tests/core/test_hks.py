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
    t = hks.time_scales(lam, m=100)
    assert np.isclose(t[0], 4 * np.log(10) / 50.0) and np.isclose(t[-1], 4 * np.log(10) / 2.0)
    assert np.allclose(np.diff(np.log(t)), np.log(t[1] / t[0]))  # log-spaced


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
