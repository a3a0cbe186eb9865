"""Metrics details a mutation pass found unpinned (issue 15): a metric no query can score is NaN, an
empty ranking is refused in words, and a class's intruders are listed most frequent first."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core import metrics


def test_a_metric_with_no_scorable_query_is_nan():
    nan = np.full(3, np.nan)
    per_query = {name: nan for name in metrics.METRICS}
    out = metrics.mean_scores(per_query)
    assert set(out) == set(metrics.METRICS)
    assert all(isinstance(v, float) and math.isnan(v) for v in out.values())


def test_an_empty_ranking_is_refused_in_words():
    with pytest.raises(ValueError, match=r"^ranking must be a non-empty 1-d array of indices$"):
        metrics.ranked_scores(np.array([], dtype=np.int64), np.array(["a", "b"]), "a")


def test_intruders_are_listed_most_frequent_first():
    # class a = shapes 0, 1, 2 (first tier: 2 each); their first tiers (hand-set below):
    #   0 -> c, a     1 -> c, b     2 -> a, a     => intruders: c twice, b once (b sorts first by name)
    labels = np.array(["a", "a", "a", "b", "c", "c"])
    d = np.full((6, 6), 50.0) + np.arange(36).reshape(6, 6) / 100  # distinct: no ties
    np.fill_diagonal(d, 0.0)
    d[0, [4, 1]] = [1.0, 2.0]
    d[1, [5, 3]] = [1.0, 2.0]
    d[2, [0, 1]] = [1.0, 2.0]
    breakdown = metrics.class_breakdown(d, labels)
    assert list(breakdown["a"]["intruders"].items()) == [("c", 2), ("b", 1)]
    assert list(metrics.scores_and_breakdown(d, labels)[1]["a"]["intruders"].items()) == [("c", 2), ("b", 1)]
