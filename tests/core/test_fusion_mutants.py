"""Fusion edge cases (issue 15 mutation pass): fuse on batches and float32 input, pairwise_l1's
exact and sampled pairs (uniform over the unordered pairs), the scale fallbacks and validation."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.fusion import FusionScales, fit_scales, fuse, pairwise_l1


def test_fuse_keeps_a_batch_of_rows_apart():
    scales = FusionScales(bof=0.5, dna=2.0, weight=3.0, count=2)
    bof = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    dna = np.array([[2.0, 4.0], [6.0, 8.0]])
    out = fuse(bof, dna, scales)
    assert out.shape == (2, 5)
    assert np.array_equal(out, np.array([[2, 4, 6, 3, 6], [8, 10, 12, 9, 12]], np.float32))


def test_fuse_computes_in_double_precision_whatever_the_input_dtype():
    rng = np.random.default_rng(3)
    scales = FusionScales(bof=0.3, dna=1.7, weight=0.9, count=30)
    bof = rng.random((50, 40)).astype(np.float32)
    dna = (rng.random((50, 30)) * 10).astype(np.float32)
    exact = fuse(bof.astype(np.float64), dna.astype(np.float64), scales)
    assert np.array_equal(fuse(bof, dna, scales), exact)
    # the float32 result is the float64 one rounded once
    assert np.array_equal(exact[:, :40], (bof.astype(np.float64) / 0.3).astype(np.float32))


def test_pairwise_l1_is_exact_for_float32_and_small_integer_input():
    x = np.array([[16777216.0, 1.0], [0.0, 0.0]], np.float32)  # 2**24 + 1 is not a float32
    assert pairwise_l1(x).tolist() == [16777217.0]
    assert pairwise_l1(np.array([[0], [200]], np.uint8)).tolist() == [200.0]


def test_two_shapes_have_one_distance_and_one_shape_is_refused_in_words():
    assert pairwise_l1(np.array([[0.0, 1.0], [3.0, -1.0]])).tolist() == [5.0]
    with pytest.raises(ValueError, match=r"^a scale needs at least 2 shapes, got 1$"):
        pairwise_l1(np.zeros((1, 3)))


def test_all_pairs_are_taken_up_to_exactly_max_pairs_then_sampled():
    x = np.array([[1.0], [2.0], [4.0], [8.0], [16.0]])  # 5 shapes, 10 pairs
    i, j = np.triu_indices(5, k=1)
    assert np.array_equal(pairwise_l1(x, max_pairs=10), np.abs(x[i] - x[j]).ravel())
    assert pairwise_l1(x, max_pairs=9).shape == (9,)


def test_sampled_pairs_are_uniform_over_the_unordered_pairs_and_never_a_shape_with_itself():
    n = 50  # 1,225 pairs, 1,200 drawn per seed; x = 2**k: every pair has its own distance
    x = 2.0 ** np.arange(n)[:, None]
    i, j = np.triu_indices(n, k=1)
    pair_of = {float(x[b, 0] - x[a, 0]): (a, b) for a, b in zip(i, j, strict=True)}
    shapes, offsets = np.zeros(n), np.zeros(n // 2 + 1)
    for seed in range(20):
        d = pairwise_l1(x, max_pairs=1200, seed=seed)
        assert d.shape == (1200,) and (d > 0).all()
        for a, b in map(pair_of.__getitem__, d.tolist()):
            shapes[[a, b]] += 1
            offsets[min(b - a, n - (b - a))] += 1  # distance round the cycle 0..n-1
    draws = 20 * 1200
    assert np.allclose(shapes / draws, 2 / n, rtol=0.15)  # every shape as often as any other
    # each cyclic offset 1..24 has n pairs, offset 25 has n / 2: as often as the pairs are many
    assert np.allclose(offsets[1:-1] / draws, n / 1225, rtol=0.15)
    assert offsets[-1] / draws == pytest.approx(n / 2 / 1225, rel=0.25)


def test_identical_shapes_get_the_unit_scale():
    same = np.ones((4, 3))
    scales = fit_scales(same, same)
    assert scales.bof == 1.0 and scales.dna == 1.0


def test_fit_scales_refuses_a_flat_bof_array_even_if_the_counts_match():
    with pytest.raises(ValueError, match="pair up"):
        fit_scales(np.zeros(3), np.zeros((3, 2)))


def test_scale_validation_edges_and_message():
    FusionScales(bof=0.5, dna=0.5, weight=0.0, count=1)  # scales below 1 are fine
    with pytest.raises(ValueError, match=r"^fusion scales must be positive \(weight >= 0, count >= 1\): "):
        FusionScales(bof=1.0, dna=0.0, weight=1.0)


def test_scales_stored_without_a_count_read_back_with_the_default_30():
    assert FusionScales.from_dict({"bof": 2, "dna": 3, "weight": 1}) == FusionScales(2.0, 3.0, 1.0, 30)
