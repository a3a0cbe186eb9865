"""Shape-DNA and D2 edge cases (issue 15 mutation pass): the unit-area default, float32 spectra,
uniform sampling by area on the triangles, and D2's last bin holding everything past max_ratio."""

from __future__ import annotations

import numpy as np

from app.core.baselines import d2_histogram, sample_surface, shape_dna
from app.core.mesh import Mesh


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
