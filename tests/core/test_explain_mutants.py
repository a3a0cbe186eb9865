"""Explain's words and vectors follow the vocabulary's run and the encode params (issue 15 mutation
pass)."""

from __future__ import annotations

import numpy as np

from app.core.descriptor import select
from app.core.explain import shape_words, vertex_words
from app.core.pipeline import ShapeDescription
from app.core.vocabulary import EncodeParams, Vocabulary


def _description(seed: int, n: int = 200, m: int = 100) -> ShapeDescription:
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
    d = _description(3)
    vocabulary = Vocabulary(centers=np.random.default_rng(4).random((12, 5)).astype(np.float32), run="run2")
    words = vertex_words(d, vocabulary)
    np.testing.assert_array_equal(words, _nearest(select(d.hks, "run2"), vocabulary.centers))


def test_a_vertex_whose_descriptor_has_zeros_gets_its_nearest_word():
    d = _description(5)
    d.hks[:20] = 0.0  # p(x) = 0 for the first 20 vertices
    centers = np.vstack([np.ones((1, 4)), np.random.default_rng(6).random((7, 4)) * 0.5]).astype(np.float32)
    vocabulary = Vocabulary(centers=centers, run="run5")
    words = vertex_words(d, vocabulary)
    np.testing.assert_array_equal(words, _nearest(select(d.hks, "run5"), centers))
    assert (words[:20] != 0).all()  # the origin is far from word 0


def test_shape_words_encode_with_the_params_given():
    d = _description(7)
    vocabulary = Vocabulary(centers=np.random.default_rng(8).random((10, 4)).astype(np.float32), run="run5")
    params = EncodeParams(mode="soft", keypoints_only=True, area_weighted=False)
    seen = shape_words(d, vocabulary, params)
    assert seen.keypoints.dtype == np.int64
    np.testing.assert_array_equal(seen.keypoints, np.flatnonzero(d.keypoints))
    np.testing.assert_array_equal(seen.bof, vocabulary.bof(d, params))
    np.testing.assert_array_equal(seen.vector, vocabulary.encode(d, params))
    assert not np.allclose(seen.bof, vocabulary.bof(d))  # the params change the vector
