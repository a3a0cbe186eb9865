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


def test_e_measure_at_its_edges():
    # a 40-long list, cutoff 32: nothing relevant in the first 32 -> E = 0 (not 0/0);
    # one of two relevant found in the first 32 -> P = 1/32, R = 1/2, E = 2PR / (P + R) = 1/17
    rel = np.zeros((2, 40), dtype=bool)
    rel[0, 35] = True
    rel[1, [0, 35]] = True
    e = metrics.relevance_scores(rel)["E"]
    assert e[0] == 0.0
    assert e[1] == pytest.approx(1 / 17)


@pytest.mark.parametrize("shape", [(5,), (3, 0)])
def test_relevance_must_be_a_non_empty_table(shape):
    with pytest.raises(ValueError, match=r"^relevance must be a \(queries, list length >= 1\) array, got"):
        metrics.relevance_scores(np.zeros(shape, dtype=bool))


def test_a_list_of_one_is_scored():
    out = metrics.relevance_scores(np.array([[True], [False]]))
    assert out["NN"].tolist() == [1.0, 0.0] and out["mAP"][0] == 1.0 and math.isnan(out["mAP"][1])


def test_ties_rank_by_index_on_long_lists():
    # psbTable breaks ties by index; an unstable sort reorders equal distances on lists this long
    n = 64
    d = np.ones((n, n))
    np.fill_diagonal(d, 0.0)
    order = metrics.rankings(d)
    assert order.tolist() == [[j for j in range(n) if j != i] for i in range(n)]


def test_two_shapes_are_enough_one_is_not():
    d = np.array([[0.0, 1.0], [1.0, 0.0]])
    assert metrics.retrieval_scores(d, np.array(["a", "a"]))["NN"] == 1.0
    with pytest.raises(ValueError, match=r"^retrieval needs at least two shapes$"):
        metrics.retrieval_scores(np.zeros((1, 1)), np.array(["a"]))


def test_labels_must_match_the_rows():
    with pytest.raises(ValueError, match=r"^labels must be \(3,\), got \(2,\)$"):
        metrics.retrieval_scores(np.zeros((3, 4)), np.array(["a", "b"]))
