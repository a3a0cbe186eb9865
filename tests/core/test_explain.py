"""Words per vertex and the per-word L1 terms (app/core/explain.py), checked against the BoF itself."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.descriptor import select
from app.core.explain import contributions, shape_words, top_words, vertex_words
from app.core.pipeline import ShapeDescription
from app.core.vocabulary import EncodeParams, Vocabulary


def _description(seed: int, n: int = 300, m: int = 100) -> ShapeDescription:
    rng = np.random.default_rng(seed)
    hks = rng.random((n, m)).astype(np.float32)
    keypoints = np.zeros(n, bool)
    keypoints[rng.choice(n, 12, replace=False)] = True
    return ShapeDescription(
        hks=hks, weights=np.full(n, 1.0 / n, np.float32), keypoints=keypoints,
        eigenvalues=np.arange(40, dtype=np.float64), input_vertices=n,
    )


@pytest.fixture
def vocabulary() -> Vocabulary:
    return Vocabulary(centers=np.random.default_rng(9).random((16, 4)).astype(np.float32), run="run5")


def test_each_vertex_gets_its_nearest_word(vocabulary: Vocabulary) -> None:
    d = _description(1)
    words = vertex_words(d, vocabulary)
    p = select(d.hks, "run5").astype(np.float64)
    brute = np.array([np.argmin(((vocabulary.centers - x) ** 2).sum(1)) for x in p])
    assert words.shape == (d.n_vertices,) and words.dtype == np.int32
    np.testing.assert_array_equal(words, brute)


def test_the_words_count_up_to_the_hard_bof(vocabulary: Vocabulary) -> None:
    d = _description(2)
    seen = shape_words(d, vocabulary, EncodeParams(mode="hard"))
    histogram = np.bincount(seen.words, minlength=vocabulary.size) / d.n_vertices
    np.testing.assert_allclose(seen.bof, histogram, atol=1e-6)  # the colours are what the index counts
    np.testing.assert_array_equal(seen.keypoints, np.flatnonzero(d.keypoints))


def test_contributions_sum_to_the_l1_distance_and_rank_largest_first() -> None:
    a = np.array([0.5, 0.1, 0.2, 0.2])
    b = np.array([0.1, 0.1, 0.5, 0.3])
    terms = contributions(a, b)
    np.testing.assert_allclose(terms, [0.4, 0.0, 0.3, 0.1])
    assert terms.sum() == pytest.approx(np.abs(a - b).sum())
    assert top_words(terms, 3).tolist() == [0, 2, 3]
    assert top_words(np.array([0.2, 0.3, 0.3]), 2).tolist() == [1, 2]  # ties: lower word first
    assert top_words(terms, 0).tolist() == []


def test_vectors_of_different_lengths_are_refused() -> None:
    with pytest.raises(ValueError, match="different lengths"):
        contributions(np.zeros(4), np.zeros(5))


# Explain's words and vectors follow the vocabulary's run and the encode params.


def _weighted_description(seed: int, n: int = 200, m: int = 100) -> ShapeDescription:
    rng = np.random.default_rng(seed)
    keypoints = np.zeros(n, bool)
    keypoints[rng.choice(n, 15, replace=False)] = True
    return ShapeDescription(
        hks=rng.random((n, m)).astype(np.float32),
        weights=rng.random(n).astype(np.float32),
        keypoints=keypoints,
        eigenvalues=np.arange(40, dtype=np.float64),
        input_vertices=n,
    )


def _nearest(p: np.ndarray, centers: np.ndarray) -> np.ndarray:
    return np.array([np.argmin(((centers.astype(np.float64) - x) ** 2).sum(1)) for x in p])


def test_words_use_the_vocabulary_run():
    d = _weighted_description(3)
    vocabulary = Vocabulary(centers=np.random.default_rng(4).random((12, 5)).astype(np.float32), run="run2")
    words = vertex_words(d, vocabulary)
    np.testing.assert_array_equal(words, _nearest(select(d.hks, "run2"), vocabulary.centers))


def test_a_vertex_whose_descriptor_has_zeros_gets_its_nearest_word():
    d = _weighted_description(5)
    d.hks[:20] = 0.0  # p(x) = 0 for the first 20 vertices
    centers = np.vstack([np.ones((1, 4)), np.random.default_rng(6).random((7, 4)) * 0.5]).astype(np.float32)
    vocabulary = Vocabulary(centers=centers, run="run5")
    words = vertex_words(d, vocabulary)
    np.testing.assert_array_equal(words, _nearest(select(d.hks, "run5"), centers))
    assert (words[:20] != 0).all()  # the origin is far from word 0


def test_shape_words_encode_with_the_params_given():
    d = _weighted_description(7)
    vocabulary = Vocabulary(centers=np.random.default_rng(8).random((10, 4)).astype(np.float32), run="run5")
    params = EncodeParams(mode="soft", keypoints_only=True, area_weighted=False)
    seen = shape_words(d, vocabulary, params)
    assert seen.keypoints.dtype == np.int64
    np.testing.assert_array_equal(seen.keypoints, np.flatnonzero(d.keypoints))
    np.testing.assert_array_equal(seen.bof, vocabulary.bof(d, params))
    np.testing.assert_array_equal(seen.vector, vocabulary.encode(d, params))
    assert not np.allclose(seen.bof, vocabulary.bof(d))  # the params change the vector
