"""Retrieval metrics on rankings worked out by hand (arithmetic written next to each expectation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core import metrics
from app.core.metrics import (
    METRICS,
    class_breakdown,
    per_query_scores,
    ranked_scores,
    rankings,
    retrieval_scores,
    scores_and_breakdown,
)

# six shapes, two classes of C = 3: each query has C - 1 = 2 relevant shapes among the other 5
LABELS6 = np.array(["a", "a", "a", "b", "b", "b"])


def test_mixed_ranking_by_hand() -> None:
    # query 0 (class a) ranks 3(b) 1(a) 4(b) 2(a) 5(b): relevance 0 1 0 1 0
    s = ranked_scores([3, 1, 4, 2, 5], LABELS6, "a")
    assert s["NN"] == 0.0  # first result is b
    assert s["FT"] == pytest.approx(1 / 2)  # first C-1 = 2 results: one relevant of 2
    assert s["ST"] == pytest.approx(2 / 2)  # first 2(C-1) = 4 results: both relevant found
    # E over min(32, 5) = 5 results: P = 2/5, R = 2/2 -> 2 / (5/2 + 1) = 4/7
    assert s["E"] == pytest.approx(4 / 7)
    # DCG = 1/log2(2) + 1/log2(4) = 1.5; ideal (relevant at 1 and 2) = 1 + 1/log2(2) = 2
    assert s["DCG"] == pytest.approx(1.5 / 2)
    # AP: relevant at ranks 2 and 4 -> precisions 1/2 and 2/4 -> mean 1/2
    assert s["mAP"] == pytest.approx(0.5)


def test_reversed_ranking_by_hand() -> None:
    # query 0 ranks every irrelevant shape first: 3 4 5 1 2 -> relevance 0 0 0 1 1
    s = ranked_scores([3, 4, 5, 1, 2], LABELS6, "a")
    assert s["NN"] == 0.0
    assert s["FT"] == 0.0  # nothing relevant in the first 2
    assert s["ST"] == pytest.approx(1 / 2)  # first 4 hold one relevant shape
    assert s["E"] == pytest.approx(4 / 7)  # first 5 = the whole list: P = 2/5, R = 1
    assert s["DCG"] == pytest.approx((1 / math.log2(4) + 1 / math.log2(5)) / 2)  # 0.4653
    assert s["mAP"] == pytest.approx((1 / 4 + 2 / 5) / 2)  # 0.325


def test_e_measure_counts_only_the_first_32() -> None:
    # class a has C = 5 (4 relevant), 35 others: 39 results; relevant at ranks 1, 3, 32 and 33
    labels = np.array(["a"] * 5 + ["b"] * 35)
    rel_ranks = [1, 3, 32, 33]
    others = iter(range(5, 40))
    relevant = iter(range(1, 5))
    ranking = [next(relevant) if r in rel_ranks else next(others) for r in range(1, 40)]
    s = ranked_scores(ranking, labels, "a")
    assert s["NN"] == 1.0
    assert s["FT"] == pytest.approx(2 / 4)  # first 4: ranks 1 and 3
    assert s["ST"] == pytest.approx(2 / 4)  # first 8: still ranks 1 and 3
    # first 32 hold 3 relevant: P = 3/32, R = 3/4 -> E = 2 / (32/3 + 4/3) = 1/6
    assert s["E"] == pytest.approx(1 / 6)
    dcg = 1 + 1 / math.log2(3) + 1 / math.log2(32) + 1 / math.log2(33)
    ideal = 1 + 1 / math.log2(2) + 1 / math.log2(3) + 1 / math.log2(4)
    assert s["DCG"] == pytest.approx(dcg / ideal)
    assert s["mAP"] == pytest.approx((1 / 1 + 2 / 3 + 3 / 32 + 4 / 33) / 4)


def test_perfect_ranking_of_20_per_class_gives_one_but_e_is_capped() -> None:
    # 30 classes x 20 shapes (SHREC'11): distance 0 inside a class, 1 across
    labels = np.repeat(np.arange(30), 20)
    d = (labels[:, None] != labels[None, :]).astype(float)
    s = retrieval_scores(d, labels)
    for name in ("NN", "FT", "ST", "DCG", "mAP"):
        assert s[name] == pytest.approx(1.0), name
    # the first 32 results hold all 19 relevant shapes: P = 19/32, R = 1 -> E = 2*19/(19+32) = 38/51
    assert s["E"] == pytest.approx(38 / 51)
    assert s["E"] == pytest.approx(0.745098, abs=1e-6)


def test_ties_are_broken_by_index() -> None:
    d = np.zeros((6, 6))  # every distance equal
    order = rankings(d)
    assert order[0].tolist() == [1, 2, 3, 4, 5]
    assert order[3].tolist() == [0, 1, 2, 4, 5]
    per = per_query_scores(d, LABELS6)
    # query 0: ranking 1 2 3 4 5 -> relevance 1 1 0 0 0: perfect
    assert per["FT"][0] == 1.0 and per["mAP"][0] == 1.0
    # query 3 (b): ranking 0 1 2 4 5 -> relevance 0 0 0 1 1, the reversed case above
    assert per["mAP"][3] == pytest.approx(0.325)
    assert per["NN"][3] == 0.0


def test_query_is_left_out_even_when_its_own_row_entry_is_largest() -> None:
    # noisy queries: row i compares a noisy i with clean shapes, so d[i, i] need not be 0
    rng = np.random.default_rng(0)
    labels = np.repeat([0, 1, 2], 4)
    d = rng.random((12, 12)) + 10.0 * (labels[:, None] != labels[None, :])
    d_big_diag = d.copy()
    np.fill_diagonal(d_big_diag, 100.0)
    d_zero_diag = d.copy()
    np.fill_diagonal(d_zero_diag, 0.0)
    a, b = retrieval_scores(d_big_diag, labels), retrieval_scores(d_zero_diag, labels)
    assert a == b
    assert a["NN"] == 1.0 and a["mAP"] == 1.0


def test_means_are_over_queries() -> None:
    # per-query values of a known matrix average to the reported means
    rng = np.random.default_rng(1)
    labels = np.repeat(np.arange(4), 5)
    d = rng.random((20, 20))
    per = per_query_scores(d, labels)
    means = retrieval_scores(d, labels)
    assert set(means) == set(METRICS)
    for name in METRICS:
        assert per[name].shape == (20,)
        assert means[name] == pytest.approx(per[name].mean())
    assert 0.0 < means["mAP"] < 1.0


def test_singleton_class_is_left_out_of_the_means() -> None:
    labels = np.array([0, 0, 1])  # shape 2 has no relevant shape
    d = np.array([[0, 1, 2], [1, 0, 2], [2, 2, 0]], dtype=float)
    per = per_query_scores(d, labels)
    assert np.isnan(per["mAP"][2])
    s = retrieval_scores(d, labels)
    assert s["NN"] == 1.0 and s["mAP"] == 1.0  # queries 0 and 1 only


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="square"):
        retrieval_scores(np.zeros((3, 4)), np.zeros(3))
    with pytest.raises(ValueError, match="labels"):
        retrieval_scores(np.zeros((3, 3)), np.zeros(4))
    with pytest.raises(ValueError, match="non-empty"):
        ranked_scores([], LABELS6, "a")


def test_average_precision_agrees_with_scikit_learn() -> None:
    # an independent implementation: sklearn's AP of the scores -distance (continuous, so no ties)
    from sklearn.metrics import average_precision_score

    rng = np.random.default_rng(7)
    labels = np.repeat(np.arange(5), 6)
    d = rng.random((30, 30))
    per = per_query_scores(d, labels)
    for i in range(30):
        others = np.arange(30) != i
        expected = average_precision_score(labels[others] == labels[i], -d[i, others])
        assert per["mAP"][i] == pytest.approx(expected)


def test_class_breakdown_by_hand() -> None:
    labels = np.array(["a", "a", "a", "b", "b", "c"])
    # query 0 ranks 3(b) 1(a) 5(c) 2(a) 4(b); query 1 ranks 0 2 ...; query 2 ranks 4(b) 5(c) 0 1 3
    d = np.full((6, 6), 9.0)
    np.fill_diagonal(d, 0.0)
    d[0, [3, 1, 5, 2, 4]] = [1, 2, 3, 4, 5]
    d[1, [0, 2, 3, 4, 5]] = [1, 2, 3, 4, 5]
    d[2, [4, 5, 0, 1, 3]] = [1, 2, 3, 4, 5]
    d[3, [4, 0, 1, 2, 5]] = [1, 2, 3, 4, 5]
    d[4, [0, 3, 1, 2, 5]] = [1, 2, 3, 4, 5]
    out = class_breakdown(d, labels)
    # AP: query 0 finds its relevant at ranks 2, 4 -> (1/2 + 2/4) / 2 = 0.5; query 1 -> 1;
    # query 2 at ranks 3, 4 -> (1/3 + 2/4) / 2
    assert out["a"]["mAP"] == pytest.approx((0.5 + 1.0 + (1 / 3 + 2 / 4) / 2) / 3)
    # first tier (2 results): query 0 -> b, a; query 1 -> a, a; query 2 -> b, c
    assert out["a"]["intruders"] == {"b": 2, "c": 1}
    assert list(out["a"]["intruders"]) == ["b", "c"]  # most frequent first
    # b: query 3 -> 4 first (AP 1, no intruder); query 4 -> 0 then 3 (AP 1/2, intruder a)
    assert out["b"]["mAP"] == pytest.approx(0.75) and out["b"]["intruders"] == {"a": 1}
    # c is a class of one: no first tier, AP undefined, left out as psbTable does
    assert math.isnan(out["c"]["mAP"]) and out["c"]["intruders"] == {}


def test_scores_and_breakdown_agree_with_the_separate_functions() -> None:
    rng = np.random.default_rng(3)
    labels = np.repeat(np.array(["a", "b", "c", "d"]), 5)
    d = rng.random((20, 20))
    scores, breakdown = scores_and_breakdown(d, labels)
    assert scores == pytest.approx(retrieval_scores(d, labels))
    assert breakdown == class_breakdown(d, labels)
    # equal class sizes: the class means average back to the overall mAP
    assert np.mean([v["mAP"] for v in breakdown.values()]) == pytest.approx(scores["mAP"])


# Metrics details: a metric no query can score is NaN, an
# empty ranking is refused in words, and a class's intruders are listed most frequent first.


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
