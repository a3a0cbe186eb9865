"""Scores of a query folder against a database folder, checked on hand-computed rankings."""

from __future__ import annotations

import numpy as np
import pytest

from app.evaluation.sets import cross_scores


def test_cross_scores_on_a_hand_computed_ranking() -> None:
    labels = np.array(["a", "a", "b", "b"])
    distances = np.array([[0.0, 3.0, 1.0, 2.0], [5.0, 4.0, 1.0, 0.0]])  # queries of classes a, b
    query_labels = np.array(["a", "b"])
    # unpaired: query 0 ranks 0(a) 2(b) 3(b) 1(a): AP = (1 + 2/4) / 2; query 1 ranks 3 2 1 0: AP = 1
    scores, per_class = cross_scores(distances, query_labels, labels, np.array([-1, -1]))
    assert scores["mAP"] == pytest.approx((0.75 + 1.0) / 2)
    assert scores["NN"] == 1.0 and per_class["a"]["mAP"] == pytest.approx(0.75)
    # paired with database shapes 0 and 3: those leave the rankings (0: 2 3 1 -> AP 1/3; 1: 2 1 0 -> AP 1)
    scores, _ = cross_scores(distances, query_labels, labels, np.array([0, 3]))
    assert scores["mAP"] == pytest.approx((1 / 3 + 1.0) / 2) and scores["NN"] == 0.5


def test_cross_scores_count_first_tier_intruders_by_hand() -> None:
    labels = np.array(["a", "a", "a", "b", "b", "c"])
    #                          a0   a1   a2   b0   b1   c0
    distances = np.array([[0.5, 3.0, 4.0, 1.0, 2.0, 0.1],   # query a: c0 a0 b0 b1 a1 a2
                          [2.0, 0.9, 5.0, 0.3, 0.2, 0.4],   # query a: b1 b0 c0 a1 a0 a2
                          [1.0, 2.0, 3.0, 0.5, 4.0, 6.0]])  # query b: b0 a0 a1 a2 b1 c0
    query_labels = np.array(["a", "a", "b"])
    # unpaired: an a-query's first tier is its first 3 results, a b-query's its first 2
    _, per_class = cross_scores(distances, query_labels, labels, np.array([-1, -1, -1]))
    assert per_class["a"]["intruders"] == {"b": 3, "c": 2}  # c0 b0 | b1 b0 c0
    assert list(per_class["a"]["intruders"]) == ["b", "c"]  # most frequent first
    assert per_class["b"]["intruders"] == {"a": 1}  # b0 a0
    # paired (a0, a1, b0 are the queries' counterparts): the tiers shrink to 2, 2 and 1
    _, per_class = cross_scores(distances, query_labels, labels, np.array([0, 1, 3]))
    assert per_class["a"]["intruders"] == {"b": 3, "c": 1}  # c0 b0 | b1 b0
    assert per_class["b"]["intruders"] == {"a": 1}  # a0
    assert set(per_class) == {"a", "b"}  # classes with queries only
