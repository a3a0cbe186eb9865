"""app.evaluation.adaptive: the served re-rank as a rank matrix the metrics can score."""

from __future__ import annotations

import numpy as np

from app.core import fusion
from app.evaluation import adaptive

# one BoF and one Shape-DNA coordinate per shape (stored weight 1): two classes of three
DB = np.array([[0.0, 0.0], [0.2, 0.1], [0.4, 0.2], [3.0, 2.0], [3.1, 2.6], [3.2, 3.2]], np.float32)


def test_each_row_is_the_rerank_then_the_rest_in_the_fixed_order_and_the_left_out_last():
    rule = fusion.AdaptiveRule(neighbours=2, expansion=1)
    queries = DB[[0, 3]] + 0.05
    r = adaptive.ranks(queries, DB, np.array([0, -1]), 1, 1.0, rule, candidates=2)
    assert r.shape == (2, 6)
    for row in r:  # a permutation of the ranks
        np.testing.assert_array_equal(np.sort(row), np.arange(6))
    assert r[0, 0] == 5  # left out: last
    # query 0 without shape 0: the re-rank of the union of its two 2-nearest searches comes first
    db_wo = np.delete(np.arange(6), 0)

    def search(v: np.ndarray, n: int) -> np.ndarray:
        d = np.abs(DB[db_wo] - v).sum(1)
        return db_wo[np.argsort(d, kind="stable")[:n]]

    ids, _ = fusion.adaptive_rerank(queries[0], search, lambda j: (j, DB[j]), 1, 1.0, rule, 2)
    np.testing.assert_array_equal(np.argsort(r[0])[:len(ids)], ids)
    # the others follow in the fixed fusion's order
    rest = [j for j in np.argsort(np.abs(DB - queries[0]).sum(1), kind="stable") if j not in ids and j != 0]
    np.testing.assert_array_equal(np.argsort(r[0])[len(ids):5], rest)


def test_with_every_shape_a_candidate_the_order_is_the_adaptive_distance():
    rule = fusion.AdaptiveRule(neighbours=3, expansion=1, distinct=0.0)  # no distinct nearest kept first
    q = np.array([[2.9, 0.1]], np.float32)  # BoF next to class 2, Shape-DNA inside class 1
    r = adaptive.ranks(q, DB, np.array([-1]), 1, 1.0, rule, candidates=6)
    w, expanded = fusion.adaptive_query(q[0], DB, 1, 1.0, rule)
    want = np.argsort(fusion.adaptive_distances(expanded, w, DB, 1, 1.0), kind="stable")
    np.testing.assert_array_equal(np.argsort(r[0]), want)
    assert set(want[:3]) == {0, 1, 2}  # the Shape-DNA's class first


def test_a_distinct_nearest_stays_first():
    """The same query with the ratio test on: its index nearest (shape 3, fused L1 2.0 against 2.6 for
    the second, 0.77 < 0.9) comes first, the rest in the re-rank's order."""
    q = np.array([[2.9, 0.1]], np.float32)
    off = adaptive.ranks(q, DB, np.array([-1]), 1, 1.0, fusion.AdaptiveRule(neighbours=3, expansion=1,
                                                                             distinct=0.0), candidates=6)
    on = adaptive.ranks(q, DB, np.array([-1]), 1, 1.0, fusion.AdaptiveRule(neighbours=3, expansion=1,
                                                                            distinct=0.9), candidates=6)
    rest = [j for j in np.argsort(off[0]) if j != 3]
    np.testing.assert_array_equal(np.argsort(on[0]), [3, *rest])
    # under the ratio (2.0 / 2.6 = 0.77 > 0.75) nothing is kept first
    strict = adaptive.ranks(q, DB, np.array([-1]), 1, 1.0, fusion.AdaptiveRule(neighbours=3, expansion=1,
                                                                                distinct=0.75), candidates=6)
    np.testing.assert_array_equal(strict, off)


def test_a_query_with_a_rim_is_ranked_as_a_piece_and_a_closed_one_as_before(monkeypatch):
    """With the local signatures, a piece's row is app.core.piece_rank's order over the fixed fusion's
    (the left-out shape still last); a closed query's row is the re-rank's, as without them."""
    from types import SimpleNamespace

    from app.core import piece_rank

    seen = {}

    def fake_order(query, order, signature_of, params, vectors=None):
        seen["order"], seen["vectors"] = order.copy(), vectors
        return order[::-1]  # any permutation of the order: the row must follow it

    monkeypatch.setattr(piece_rank, "piece_order", fake_order)
    rule = fusion.AdaptiveRule(neighbours=2, expansion=1)
    queries = DB[[0, 3]] + 0.05
    piece, closed = SimpleNamespace(rim=1.0), SimpleNamespace(rim=0.0)
    left_out = np.array([0, -1])
    with_locals = adaptive.ranks(queries, DB, left_out, 1, 1.0, rule, candidates=2,
                                 query_locals=[piece, closed], db_locals=[closed] * 6)
    without = adaptive.ranks(queries, DB, left_out, 1, 1.0, rule, candidates=2)
    fixed = [j for j in np.argsort(np.abs(DB - queries[0]).sum(1), kind="stable") if j != 0]
    np.testing.assert_array_equal(seen["order"], fixed)  # the global order, the left-out shape not in it
    np.testing.assert_array_equal(seen["vectors"], DB)  # the stored vectors, for the peers' scores
    np.testing.assert_array_equal(np.argsort(with_locals[0])[:5], fixed[::-1])
    assert with_locals[0, 0] == 5  # left out: last
    np.testing.assert_array_equal(with_locals[1], without[1])
