"""Shape-DNA and D2: the mathematics they promise (spectrum of a sphere, invariances, separation)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.baselines import (
    d2_histogram,
    euclidean_distance,
    sample_surface,
    shape_dna,
    shape_dna_of_mesh,
)
from app.core.mesh import Mesh
from app.core.vocabulary import l1_distance


def _mesh(tm: trimesh.Trimesh) -> Mesh:
    return Mesh(np.asarray(tm.vertices, float), np.asarray(tm.faces, np.int64))


def _rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.fixture(scope="module")
def sphere() -> Mesh:
    return _mesh(trimesh.creation.icosphere(subdivisions=3, radius=1.0))  # 642 vertices


@pytest.fixture(scope="module")
def cube() -> Mesh:
    return _mesh(trimesh.creation.box(extents=(1, 1, 1)).subdivide().subdivide().subdivide())


@pytest.fixture(scope="module")
def capsule() -> Mesh:
    return _mesh(trimesh.creation.capsule(height=3.0, radius=0.6, count=[24, 24]))


@pytest.mark.slow  # a large eigenproblem of a fine sphere
def test_shape_dna_of_a_sphere_follows_the_spectrum() -> None:
    # sphere: λ = l(l+1)/r² with multiplicity 2l+1, area 4πr² -> λ·A = 4π l(l+1)
    # first three non-zero (l = 1): 8π, divided by i = 1, 2, 3
    dna = shape_dna_of_mesh(_mesh(trimesh.creation.icosphere(subdivisions=4, radius=2.0)), count=8)
    expected = np.array([8, 8, 8, 24, 24, 24, 24, 24]) * np.pi / np.arange(1, 9)
    np.testing.assert_allclose(dna, expected, rtol=0.01)


def test_shape_dna_skips_zero_eigenvalues_and_normalises_by_area() -> None:
    lam = np.array([0.0, 1e-14, 2.0, 3.0, 8.0])  # two components: two zeros
    np.testing.assert_allclose(shape_dna(lam, area=0.5, count=3), [1.0, 1.5 / 2, 4.0 / 3])
    with pytest.raises(ValueError, match="needs 4"):
        shape_dna(lam, count=4)


def test_shape_dna_invariant_to_rotation_translation_and_scale(capsule: Mesh) -> None:
    base = shape_dna_of_mesh(capsule)
    moved = Mesh(3.7 * capsule.vertices @ _rotation(1).T + [5.0, -2.0, 1.0], capsule.faces)
    np.testing.assert_allclose(shape_dna_of_mesh(moved), base, rtol=1e-6)


def test_shape_dna_tells_shapes_apart(sphere: Mesh, capsule: Mesh) -> None:
    a, b = shape_dna_of_mesh(sphere), shape_dna_of_mesh(capsule)
    d = euclidean_distance(np.stack([a, b]), np.stack([a, b]))
    assert d[0, 0] == pytest.approx(0.0, abs=1e-9)
    assert d[0, 1] > 0.05 * np.linalg.norm(a)


def test_d2_is_a_deterministic_distribution(sphere: Mesh) -> None:
    h = d2_histogram(sphere, seed=3)
    assert h.shape == (64,) and h.sum() == pytest.approx(1.0) and (h >= 0).all()
    np.testing.assert_array_equal(h, d2_histogram(sphere, seed=3))
    # sphere: distances of points on a sphere are at most the diameter = 2r and mean 4r/3,
    # so no ratio above 2 / (4/3) = 1.5 (bins of width 4/64: nothing past bin 24)
    assert h[25:].sum() < 1e-3


def test_d2_of_sphere_and_cube_differ(sphere: Mesh, cube: Mesh) -> None:
    s1, s2 = d2_histogram(sphere, seed=0), d2_histogram(sphere, seed=1)
    c1 = d2_histogram(cube, seed=0)
    d = l1_distance(np.stack([s1, s2]), np.stack([c1]))
    sampling_noise = l1_distance(s1[None], s2[None])[0, 0]
    assert d.min() > 3.0 * sampling_noise
    assert d.min() > 0.1


def test_d2_invariant_to_rigid_motion_and_scale(cube: Mesh) -> None:
    h = d2_histogram(cube, seed=5)
    moved = Mesh(0.01 * cube.vertices @ _rotation(2).T + [1.0, 2.0, 3.0], cube.faces)
    # the same seed samples the same faces and barycentrics: ratios agree to round-off
    assert l1_distance(h[None], d2_histogram(moved, seed=5)[None])[0, 0] < 1e-3


def test_d2_of_a_surface_without_area_says_so() -> None:
    # collinear corners: an extent but no area (before, NumPy's "probabilities contain NaN")
    flat = Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]), np.array([[0, 1, 2], [1, 2, 3]]))
    with pytest.raises(ValueError, match="^cannot sample a surface of zero area$"):
        d2_histogram(flat)


# Shape-DNA and D2 edge cases: the unit-area default, float32 spectra,
# uniform sampling by area on the triangles, and D2's last bin holding everything past max_ratio.


def _two_triangles() -> Mesh:
    """In the plane z = 0: a right triangle of area 1/2 (x + y <= 1) and one of area 3/2 (x >= 2)."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [5, 0, 0], [2, 1, 0]], np.float64)
    return Mesh(v, np.array([[0, 1, 2], [3, 4, 5]], np.int64))


def test_shape_dna_defaults_to_the_unit_area():
    lam = np.array([0.0, 2.0, 6.0, 12.0])
    assert shape_dna(lam, count=3).tolist() == [2.0, 3.0, 4.0]


def test_shape_dna_of_a_float32_spectrum_is_computed_in_double_precision():
    lam = np.array([0.0, 1.1, 2.3, 3.7, 5.9], np.float32)
    exact = shape_dna(lam.astype(np.float64), area=0.37, count=4)
    assert np.array_equal(shape_dna(lam, area=0.37, count=4), exact)


def test_samples_lie_on_the_triangles_and_follow_their_areas():
    p = sample_surface(_two_triangles(), 40_000, np.random.default_rng(0))
    assert np.all(p[:, 2] == 0)
    small = p[:, 0] < 1.5
    assert abs(small.mean() - 0.25) < 0.01  # area 1/2 of 2
    x, y = p[small, 0], p[small, 1]
    assert x.min() >= 0 and y.min() >= 0 and (x + y).max() <= 1 + 1e-12
    assert np.allclose([x.mean(), y.mean()], 1 / 3, atol=0.01)  # uniform: the centroid on average
    big = p[~small]
    assert big[:, 0].min() >= 2 and big[:, 1].min() >= 0 and (big[:, 0] + 3 * big[:, 1]).max() <= 5 + 1e-12


def test_d2_bins_the_same_samples_whatever_the_range_and_past_max_ratio_is_the_last_bin():
    mesh = _two_triangles()
    fine = d2_histogram(mesh, pairs=4000, bins=16, max_ratio=4.0)  # bins 0.25 wide
    narrow = d2_histogram(mesh, pairs=4000, bins=2, max_ratio=0.5)  # [0, 0.25), [0.25, 0.5]+
    assert 0 < fine[0] < 1
    assert narrow.sum() == 1.0
    assert narrow[0] == fine[0] and narrow[1] == 1.0 - fine[0]
