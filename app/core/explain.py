"""Why two shapes are near: which geometric word each vertex is, and which words make their BoF distance.

Pure numerics over a description and a vocabulary (no storage, no HTTP). The words are the hard vector
quantisation of p(x) (eq. 6: the nearest centre), whatever mode the index encodes with: one colour per
vertex. The contributions are the terms of the L1 distance between two BoF vectors, |a_i - b_i|, so they
sum to that distance and the largest say which words separate the shapes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.descriptor import select
from app.core.pipeline import ShapeDescription
from app.core.vocabulary import EncodeParams, Vocabulary


def vertex_words(description: ShapeDescription, vocabulary: Vocabulary) -> np.ndarray:
    """(n,) int32 word id of every vertex at the canonical resolution: argmin_j ||p(x) - c_j||²."""
    p = select(description.hks, vocabulary.run).astype(np.float64)  # (n, d)
    c = vocabulary.centers.astype(np.float64)  # (v, d)
    sq = (p * p).sum(1)[:, None] - 2.0 * p @ c.T + (c * c).sum(1)[None, :]  # (n, v)
    return sq.argmin(axis=1).astype(np.int32)


def contributions(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(v,) per-word terms |a_i - b_i| of the L1 distance between BoF vectors a, b (both (v,))."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.shape != b.shape:
        raise ValueError(f"BoF vectors of different lengths: {a.shape} and {b.shape}")
    return np.abs(a - b)


def top_words(terms: np.ndarray, count: int) -> np.ndarray:
    """Indices of the `count` largest terms, largest first (ties: lower word id first)."""
    order = np.lexsort((np.arange(len(terms)), -terms))  # last key sorts first
    return order[: max(0, count)]


@dataclass(frozen=True)
class ShapeWords:
    """One shape seen through a vocabulary."""

    words: np.ndarray  # (n,) int32 word per vertex
    keypoints: np.ndarray  # (k,) int64 vertex indices of the keypoints
    bof: np.ndarray  # (v,) float32 BoF histogram under the encode params
    vector: np.ndarray  # what the index compares: BoF, fused with Shape-DNA when the vocabulary says so


def shape_words(description: ShapeDescription, vocabulary: Vocabulary, params: EncodeParams) -> ShapeWords:
    return ShapeWords(
        words=vertex_words(description, vocabulary),
        keypoints=np.flatnonzero(description.keypoints).astype(np.int64),
        bof=vocabulary.bof(description, params),
        vector=vocabulary.encode(description, params),
    )
