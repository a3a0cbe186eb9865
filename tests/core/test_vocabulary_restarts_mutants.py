"""Vocabulary.fit_features restarts k-means (issue 15, sixth pass: `n_init=4` dropped survived).

One k-means++ run can seed two centres in one cluster and leave another without one: a local optimum.
The vocabulary keeps the best of several seeded runs, so on well-separated clusters it finds the
clustering a single run often misses."""

from __future__ import annotations

import itertools

import numpy as np

from app.core.vocabulary import Vocabulary


def nine_clusters() -> tuple[np.ndarray, float]:
    """(N, 4) points around 9 centres 4 apart on a grid, spread 0.5, alternately 6 and 60 points (small
    clusters next to big ones are what a k-means++ seeding misses), and the inertia of the true
    partition: with clusters this far apart it is the optimum."""
    rng = np.random.default_rng(0)
    centres = np.zeros((9, 4))
    centres[:, :2] = 4.0 * np.array(list(itertools.product(range(3), repeat=2)))
    sizes = [60 if i % 2 else 6 for i in range(9)]
    points = [c + 0.5 * rng.normal(size=(s, 4)) for c, s in zip(centres, sizes, strict=True)]
    optimum = sum(float(((p - p.mean(axis=0)) ** 2).sum()) for p in points)
    return np.concatenate(points), optimum


def test_the_vocabulary_is_the_best_of_several_k_means_runs():
    """With one k-means++ run per fit, 9 of these 20 seeds end in a local optimum (scikit-learn 1.9); the
    best of 4 runs misses only if all 4 do (1 seed of 20; the best of 5: none). Allowing 4 misses keeps
    the test independent of scikit-learn's exact random streams: were each run to miss with probability
    0.45, the best of 4 would miss 5 or more of 20 about once in 900, one run 4 or fewer about once in 50."""
    features, optimum = nine_clusters()
    inertias = [Vocabulary.fit_features(features, size=9, run="run5", seed=seed).metadata["inertia"]
                for seed in range(20)]
    assert min(inertias) >= optimum * (1 - 1e-9)  # nothing beats the true partition
    found = sum(inertia <= optimum * (1 + 1e-9) for inertia in inertias)
    assert found >= 16, inertias
