"""benchmarks.partial_ideas: the aggregations, on tables small enough to compute by hand."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.partial import LocalSignature
from benchmarks.partial_ideas import Shape, Table, mutual, vote, whitening


def _table() -> Table:
    """One scale hypothesis, query samples a (area 0.6) and b (0.4), two candidates of two samples.
    Candidate 0: a -> sample 0, b -> sample 0; sample 0's nearest query sample is a, sample 1's is b.
    Candidate 1: a -> sample 1, b -> sample 0; sample 0's nearest is b, sample 1's is a."""
    near = np.array([[[0.1, 0.3], [0.2, 0.1]]], np.float32)  # (1, p=2, N=2)
    near_i = np.array([[[0, 1], [0, 0]]], np.int16)
    back = np.zeros((1, 2, 2), np.float32)
    back_i = np.array([[[0, 1], [1, 0]]], np.int16)  # (1, N, s)
    return Table(near, near_i, back, back_i, np.array([[0.6, 0.4]]))


def test_mutual_counts_the_query_area_matched_one_to_one():
    # candidate 0: a <-> sample 0 is mutual, b -> sample 0 -> a is not: 0.6; candidate 1: both mutual
    assert mutual(_table(), np.array([0, 0])) == pytest.approx([0.6, 1.0])


def test_vote_counts_the_query_area_for_which_a_candidate_is_among_the_best():
    # a prefers candidate 0 (0.1 < 0.3), b candidate 1 (0.1 < 0.2)
    assert vote(_table(), np.array([0, 0]), 1) == pytest.approx([0.6, 0.4])
    assert vote(_table(), np.array([0, 0]), 2) == pytest.approx([1.0, 1.0])


def test_whitening_is_lower_triangular_and_whitens_the_model_slopes():
    rng = np.random.default_rng(0)
    mix = np.tril(rng.normal(size=(16, 16))) + 4 * np.eye(16)
    slopes = (rng.normal(size=(500, 21)) @ np.pad(mix, ((0, 5), (0, 5)))).astype(np.float32)
    sig = LocalSignature(slopes, np.full(500, 1 / 500, np.float32), np.full(500, 21, np.int16), 0.0)
    w = whitening([Shape(np.zeros(1), sig, np.zeros((500, 22)))])
    assert np.allclose(np.triu(w, 1), 0.0)  # a prefix of whitened slopes reads the same prefix only
    z = slopes[:, :16].astype(np.float64) @ w.T
    assert np.allclose(np.cov(z, rowvar=False), np.eye(16), atol=1e-6)
