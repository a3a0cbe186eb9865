"""The query-adaptive re-rank of app.core.fusion: agreement ratio, weight, expansion, distances by hand."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.fusion import (
    AdaptiveRule,
    FusionScales,
    adaptive_distances,
    adaptive_query,
    adaptive_rerank,
    agreement,
    distinct_first,
    fuse,
    is_closed,
    is_noisy,
    query_weight,
    split_parts,
)

# four candidates, one BoF and one Shape-DNA coordinate each (already over their scales)
BOFS = np.array([[0.0], [1.0], [10.0], [14.0]])
DNAS = np.array([[0.0], [1.0], [5.0], [7.0]])


def test_split_parts_undoes_the_stored_weight_and_scales():
    scales = FusionScales(bof=0.5, dna=4.0, weight=0.25, count=2)
    v = fuse(np.array([1.0, 2.0, 3.0]), np.array([8.0, 12.0]), scales)
    b, d = split_parts(v, 3, scales.weight)
    np.testing.assert_allclose(b, [2.0, 4.0, 6.0])
    np.testing.assert_allclose(d, [2.0, 3.0])
    with pytest.raises(ValueError, match="no Shape-DNA part"):
        split_parts(v, 3, 0.0)


def test_agreement_by_hand():
    # BoF's two nearest: candidates 0, 1; the Shape-DNA's: 3, 2.
    # In DNA, {3, 2} spread |7 - 5| = 2 and {0, 1} spread 1: x_bof = 2 / 1.
    # In BoF, {0, 1} spread 1 and {3, 2} spread 4: x_dna = 1 / 4.  r = 2 / (1/4) = 8.
    b, d = np.array([0.1, 0.2, 0.3, 0.4]), np.array([0.4, 0.3, 0.2, 0.1])
    assert agreement(b, d, BOFS, DNAS, k=2) == pytest.approx(8.0)
    # the roles of the parts exchanged: the reciprocal
    assert agreement(d, b, DNAS, BOFS, k=2) == pytest.approx(1 / 8.0)


def test_agreement_is_free_of_each_parts_scale_and_of_the_candidates_order():
    rng = np.random.default_rng(3)
    bofs, dnas = rng.random((30, 5)), rng.random((30, 4))
    q_b, q_d = rng.random(5), rng.random(4)
    b, d = np.abs(bofs - q_b).sum(1), np.abs(dnas - q_d).sum(1)
    r = agreement(b, d, bofs, dnas, k=6)
    assert agreement(7 * b, 0.2 * d, 7 * bofs, 0.2 * dnas, k=6) == pytest.approx(r)
    p = rng.permutation(30)
    assert agreement(b[p], d[p], bofs[p], dnas[p], k=6) == pytest.approx(r)


def test_agreement_without_evidence_is_neutral():
    same = np.zeros((4, 1))
    assert agreement(np.arange(4.0), np.arange(4.0), same, same, k=2) == 1.0  # duplicates: no spread
    assert agreement(np.array([1.0]), np.array([1.0]), same[:1], same[:1], k=10) == 1.0  # one candidate


def test_query_weight_rises_only_below_the_pivot():
    rule = AdaptiveRule(weight=0.4, pivot=0.9, power=3.0)
    assert query_weight(0.9, rule) == pytest.approx(0.4)
    assert query_weight(8.0, rule) == pytest.approx(0.4)
    assert query_weight(0.45, rule) == pytest.approx(0.4 * 2**3)


def test_a_closed_query_weighs_its_shape_dna_at_least_as_the_fixed_fusion():
    rule = AdaptiveRule(weight=0.4, pivot=0.9, power=3.0, closed_weight=1.0, closed_rim=0.05)
    assert query_weight(0.9, rule, rim=0.0) == pytest.approx(1.0)  # closed: the floor, not w0
    assert query_weight(0.9, rule, rim=0.05) == pytest.approx(1.0)  # at the threshold: closed
    assert query_weight(0.45, rule, rim=0.0) == pytest.approx(0.4 * 2**3)  # above the floor: unchanged
    assert query_weight(0.9, rule, rim=0.3) == pytest.approx(0.4)  # open: w0
    assert query_weight(0.9, rule, rim=None) == pytest.approx(0.4)  # unknown (no local signature): open
    assert query_weight(0.9, rule, rim=float("nan")) == pytest.approx(0.4)
    assert is_closed(0.0, rule) and not is_closed(0.051, rule) and not is_closed(None, rule)


def test_a_closed_querys_floor_changes_the_ranking_where_the_shape_dna_disagrees():
    """Candidate 0 is nearer by BoF, candidate 1 by Shape-DNA (both parts over their scales): at w0 = 0.4
    the BoF leads (0 + 0.4 × 2 < 1 + 0.4 × 0); a closed query's w = 1 puts candidate 1 first (2 > 1)."""
    cands = np.array([[0.0, 2.0], [1.0, 0.0], [9.0, 9.0], [9.5, 9.5]], np.float32)  # stored weight 1
    query = np.zeros(2, np.float32)
    rule = AdaptiveRule(weight=0.4, neighbours=2, expansion=0)
    w_open, e = adaptive_query(query, cands, 1, 1.0, rule, rim=0.5)
    w_closed, _ = adaptive_query(query, cands, 1, 1.0, rule, rim=0.0)
    assert w_open < 1.0 <= w_closed
    assert np.argmin(adaptive_distances(e, w_open, cands, 1, 1.0)) == 0
    assert np.argmin(adaptive_distances(e, w_closed, cands, 1, 1.0)) == 1


def test_a_noisy_closed_query_weighs_its_shape_dna_at_least_the_noisy_weight():
    rule = AdaptiveRule(weight=0.4, pivot=0.9, power=3.0, closed_weight=1.0, noisy_below=0.0,
                        noisy_weight=4.0)
    assert query_weight(0.9, rule, rim=0.0, noise=-0.5) == pytest.approx(4.0)  # closed and noisy
    assert query_weight(0.9, rule, rim=0.0, noise=0.8) == pytest.approx(1.0)  # closed and clean
    assert query_weight(0.9, rule, rim=0.0, noise=0.0) == pytest.approx(1.0)  # at the threshold: clean
    assert query_weight(0.9, rule, rim=0.3, noise=-0.5) == pytest.approx(0.4)  # open: the spectrum moves
    assert query_weight(0.9, rule, rim=0.0, noise=None) == pytest.approx(1.0)  # unknown: clean
    assert query_weight(0.9, rule, rim=0.0, noise=float("nan")) == pytest.approx(1.0)
    assert query_weight(0.09, rule, rim=0.0, noise=-0.5) == pytest.approx(400.0)  # above the floor: unchanged
    assert is_noisy(-0.01, rule) and not is_noisy(0.0, rule) and not is_noisy(None, rule)


def test_the_noisy_floor_changes_the_ranking_where_the_shape_dna_disagrees():
    """Candidate 0 is nearer by BoF (0 + w × 2), candidate 1 by Shape-DNA (3 + w × 0): a clean closed
    query (w = 1) keeps candidate 0 first (2 < 3), a noisy one (w = 4) puts candidate 1 first (8 > 3)."""
    cands = np.array([[0.0, 2.0], [3.0, 0.0], [9.0, 9.0], [9.5, 9.5]], np.float32)  # stored weight 1
    query = np.zeros(2, np.float32)
    rule = AdaptiveRule(weight=0.4, neighbours=2, expansion=0, noisy_weight=4.0)
    w_clean, e = adaptive_query(query, cands, 1, 1.0, rule, rim=0.0, noise=0.8)
    w_noisy, _ = adaptive_query(query, cands, 1, 1.0, rule, rim=0.0, noise=-0.5)
    assert w_clean == pytest.approx(1.0) and w_noisy == pytest.approx(4.0)
    assert np.argmin(adaptive_distances(e, w_clean, cands, 1, 1.0)) == 0
    assert np.argmin(adaptive_distances(e, w_noisy, cands, 1, 1.0)) == 1


@pytest.mark.parametrize("bad", [dict(weight=0), dict(pivot=0), dict(power=-1), dict(neighbours=1),
                                 dict(expansion=-1), dict(closed_weight=-1), dict(closed_rim=-0.1),
                                 dict(distinct=-0.1), dict(distinct=1.5), dict(noisy_below=1.5),
                                 dict(noisy_weight=-1)])
def test_rule_validation(bad):
    with pytest.raises(ValueError, match="invalid adaptive fusion rule"):
        AdaptiveRule(**bad)


def test_expansion_and_distances_by_hand():
    # fused layout [bof (1,), 0.5 × dna (1,)] (stored weight 0.5); the query sits between 0 and 1
    stored = 0.5
    cands = np.array([[0.0, 0.0], [1.0, 0.5], [10.0, 2.5], [14.0, 3.5]], np.float32)  # = BOFS, 0.5 × DNAS
    query = np.array([0.4, 0.25], np.float32)  # bof 0.4, dna 0.5
    rule = AdaptiveRule(weight=1.0, pivot=0.9, power=3.0, neighbours=2, expansion=1)
    w, expanded = adaptive_query(query, cands, 1, stored, rule)
    # b = [0.4, 0.6, 9.6, 13.6], d = [0.5, 0.5, 4.5, 6.5]: both parts' 2 nearest are {0, 1}, r = 1: w = w0
    assert w == pytest.approx(1.0)
    # the nearest by b + w d is candidate 0 (0.9 against 1.1): expanded = (query + cand 0) / 2
    np.testing.assert_allclose(expanded, [0.2, 0.125])
    # distances of the expanded query (bof 0.2, dna 0.25): |0.2 - x| + w |0.25 - y|
    np.testing.assert_allclose(adaptive_distances(expanded, w, cands, 1, stored),
                               [0.2 + 0.25, 0.8 + 0.75, 9.8 + 4.75, 13.8 + 6.75], rtol=1e-6)


def test_no_expansion_keeps_the_query():
    cands = np.array([[0.0, 0.0], [1.0, 0.5], [10.0, 2.5]], np.float32)
    query = np.array([0.4, 0.25], np.float32)
    _, expanded = adaptive_query(query, cands, 1, 0.5, AdaptiveRule(expansion=0, neighbours=2))
    np.testing.assert_array_equal(expanded, query)


def test_a_noisy_query_whose_bof_points_at_the_wrong_class_is_ranked_by_its_shape_dna():
    """Class A = candidates 0-2, class B = 3-5, apart in both parts. The query (class A) has a BoF
    that landed next to class B and a Shape-DNA inside class A. The BoF's nearest {3, 4, 5} are spread
    out in Shape-DNA, the Shape-DNA's nearest {0, 1, 2} less so in BoF: r < 1, the Shape-DNA leads."""
    bofs = np.array([[0.0], [0.2], [0.4], [3.0], [3.1], [3.2]])
    dnas = np.array([[0.0], [0.1], [0.2], [2.0], [2.6], [3.2]])
    stored = 1.0
    cands = np.hstack([bofs, dnas]).astype(np.float32)
    query = np.array([2.9, 0.1], np.float32)  # BoF next to class B, Shape-DNA inside class A
    served = np.abs(cands - query).sum(1)  # BoF + 1 × DNA
    assert set(np.argsort(served)[:3]) != {0, 1, 2}  # the fixed fusion mixes the classes
    rule = AdaptiveRule(weight=0.4, pivot=0.9, power=3.0, neighbours=3, expansion=1)
    w, expanded = adaptive_query(query, cands, 1, stored, rule)
    # x_bof = spread_dna{0,1,2} / spread_dna{3,4,5} = (0.4/3) / (2.4/3) = 1/6;
    # x_dna = spread_bof{3,4,5} / spread_bof{0,1,2} = (0.4/3) / (0.8/3) = 1/2;  r = 1/3
    assert w == pytest.approx(0.4 * (0.9 * 3) ** 3)
    order = np.argsort(adaptive_distances(expanded, w, cands, 1, stored), kind="stable")
    assert set(order[:3]) == {0, 1, 2}


def test_rerank_ranks_the_union_of_both_searches_by_the_adaptive_distance():
    """A brute-force 'index' of six vectors (ids 10-15) answering 2 candidates per search: the union of
    the query's and the expanded query's answers is ranked by adaptive_distances, nothing else."""
    stored = 1.0
    db = np.array([[0.0, 0.0], [0.2, 0.1], [0.4, 0.2], [3.0, 2.0], [3.1, 2.6], [3.2, 3.2]], np.float32)
    ids = np.arange(10, 16)
    searched: list[np.ndarray] = []

    def search(vector: np.ndarray, n: int) -> np.ndarray:
        searched.append(vector)
        return ids[np.argsort(np.abs(db - vector).sum(1), kind="stable")[:n]]

    def vectors_of(wanted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return wanted, db[wanted - 10]

    rule = AdaptiveRule(weight=0.4, neighbours=2, expansion=1, distinct=0.0)
    query = np.array([0.5, 0.25], np.float32)
    got, dist = adaptive_rerank(query, search, vectors_of, 1, stored, rule, candidates=2)
    assert len(searched) == 2
    w, expanded = adaptive_query(query, db[[2, 1]], 1, stored, rule)  # the first answer: ids 12, 11
    np.testing.assert_array_equal(searched[1], expanded)
    union = np.union1d([12, 11], ids[np.argsort(np.abs(db - expanded).sum(1), kind="stable")[:2]])
    want = adaptive_distances(expanded, w, db[union - 10], 1, stored)
    np.testing.assert_array_equal(got, union[np.argsort(want, kind="stable")])
    np.testing.assert_allclose(dist, np.sort(want))
    assert np.all(np.diff(dist) >= 0)


def test_rerank_of_an_empty_answer_is_empty():
    got, dist = adaptive_rerank(np.zeros(2, np.float32), lambda v, n: np.zeros(0, np.int64),
                                lambda i: (i, np.zeros((0, 2), np.float32)), 1, 1.0, AdaptiveRule(), 5)
    assert got.shape == dist.shape == (0,)


def test_distinct_first_is_lowes_ratio_test():
    assert distinct_first(np.array([5.0, 1.0, 2.0]), 0.9) == 1  # 1 < 0.9 × 2
    assert distinct_first(np.array([5.0, 1.9, 2.0]), 0.9) is None  # 1.9 >= 1.8
    assert distinct_first(np.array([0.0, 0.0, 3.0]), 0.9) is None  # two copies: neither is distinct
    assert distinct_first(np.array([0.0, 3.0]), 0.9) == 0  # one stored copy at 0
    assert distinct_first(np.array([1.0]), 0.9) is None  # one candidate: no second to compare
    assert distinct_first(np.array([1.0, 5.0]), 0.0) is None  # off


def test_a_distinct_nearest_is_not_demoted_by_the_expansion():
    """Candidate 0 is the query's distinct nearest (fused L1 0.3 against 1.0); the expansion toward the
    tight group 1-3 would rank the group first. With the ratio test it stays first, with its own
    re-rank distance; without it the group leads."""
    db = np.array([[0.0, 0.3], [1.0, 0.0], [1.05, 0.05], [1.1, 0.0], [9.0, 9.0]], np.float32)
    ids = np.arange(5)

    def search(v: np.ndarray, n: int) -> np.ndarray:
        return ids[np.argsort(np.abs(db - v).sum(1), kind="stable")[:n]]

    query = np.array([0.0, 0.0], np.float32)  # L1: 0.3, 1.0, 1.1, 1.1, 18
    base = dict(weight=1.0, neighbours=2, expansion=3)
    def rerank(distinct: float) -> tuple[np.ndarray, np.ndarray]:
        rule = AdaptiveRule(**base, distinct=distinct)
        return adaptive_rerank(query, search, lambda j: (j, db[j]), 1, 1.0, rule, 5)

    (off, d_off), (on, d_on) = rerank(0.0), rerank(0.9)
    assert off[0] != 0 and on[0] == 0
    np.testing.assert_array_equal(on[1:], [j for j in off if j != 0])
    assert d_on[0] == pytest.approx(d_off[list(off).index(0)])  # its own distance, not the next's
