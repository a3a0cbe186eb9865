"""app.core.piece_rank: a piece's candidates, scores and order, as the service and the evaluation run them."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.config import DescribeSettings
from app.core import piece_rank
from app.core.mesh import Mesh
from app.core.partial_match import CAP, COPY_DISTANCE, PEER_RADIUS, PEER_WEIGHT, PartialMatch
from app.core.pipeline import LOCAL, describe
from app.services import partial as partial_service
from app.services import search as search_service
from tests.api.test_partial_api import _half, _shapes


def _match(distance: float, score: float | None = None) -> SimpleNamespace:
    return SimpleNamespace(distance=distance, score=distance if score is None else score)


def test_a_rim_makes_a_piece_unless_the_caller_says_otherwise():
    closed, open_ = SimpleNamespace(rim=0.0), SimpleNamespace(rim=piece_rank.RIM_PARTIAL)
    assert not piece_rank.is_piece(closed) and piece_rank.is_piece(open_) and not piece_rank.is_piece(None)
    assert piece_rank.is_piece(closed, True) and not piece_rank.is_piece(open_, False)


def test_the_candidates_are_the_global_head_and_the_coarse_nearest_in_global_order():
    coarse = [_match(d) for d in (5.0, 4.0, 3.0, 0.1, 9.0, 0.2)] + [None, _match(0.0)]
    assert piece_rank.chosen(8, coarse, keep=2, coarse_keep=3) == [0, 1, 3, 5, 7]
    assert piece_rank.chosen(3, [], keep=5) == [0, 1, 2]  # a collection no larger than the head: all


def test_by_score_puts_the_unscored_last_and_breaks_ties_by_global_order():
    found = [None, _match(0.0, 0.5), _match(0.0, 0.1), None, _match(0.0, 0.5)]
    assert piece_rank.by_score(found) == [2, 1, 4, 0, 3]


@pytest.fixture(scope="module")
def signatures() -> tuple:
    """The local signatures of the five bodies and the torus, and of a half of the quadruped."""
    params = DescribeSettings(k=300, m=20, target_vertices=1000).params()
    shapes = _shapes()
    names = list(shapes)
    def local(mesh) -> object:
        return describe(Mesh(np.asarray(mesh.vertices, float), np.asarray(mesh.faces)), params).local
    return names, [local(shapes[n]) for n in names], local(_half(shapes["quadruped"]))


def test_a_half_ranks_its_whole_first_and_every_model_once(signatures):
    names, sigs, half = signatures
    assert piece_rank.is_piece(half)
    order = np.arange(len(sigs))[::-1]  # a global order that puts the quadruped anywhere but first
    ranked = piece_rank.piece_order(half, order, sigs.__getitem__, LOCAL)
    assert names[ranked[0]] == "quadruped"
    assert sorted(ranked.tolist()) == list(range(len(sigs)))


def test_the_evaluations_order_is_the_services(signatures, monkeypatch):
    """search._scored (the service, deadlines lifted, the coarse pass made to choose) against
    piece_order on the same global order: the same candidates in the same order."""
    _, sigs, half = signatures
    monkeypatch.setattr(partial_service, "local_of", lambda ctx, i: sigs[i])
    monkeypatch.setattr(partial_service, "GLOBAL_KEEP", 2)
    monkeypatch.setattr(partial_service, "COARSE_KEEP", 2)
    vectors = np.random.default_rng(3).random((len(sigs), 8))  # the stored fused vectors, by model id
    monkeypatch.setattr(partial_service, "stored_vectors", lambda ctx, vid, ids: vectors[list(ids)])
    order = np.array([5, 4, 3, 2, 1, 0])
    hits = [search_service.Hit(SimpleNamespace(id=int(i)), 0.0, r + 1) for r, i in enumerate(order)]
    served = search_service._scored(None, half, hits, len(order), True,  # type: ignore[arg-type]
                                    vocabulary_id=1)
    ours = piece_rank.piece_order(half, order, sigs.__getitem__, LOCAL, keep=2, coarse_keep=2,
                                  vectors=vectors)
    assert [h.model.id for h in served] == ours[: len(served)].tolist() and len(served) == 4


def _own(own: float) -> PartialMatch:
    """A match whose own score is `own` (no vote, no mutual share)."""
    return PartialMatch(distance=own, forward=1.0, reverse=1.0, scale=1.0)


def test_peers_are_the_mean_own_score_of_the_nearest_fellow_candidates():
    found = [_own(s) for s in (1.0, 2.0, 4.0, 10.0)]
    line = np.array([[0.0], [1.0], [3.0], [100.0]])  # L1 between the stored vectors: positions on a line
    one = piece_rank.with_peers(found, line, count=1, radius=np.inf)
    assert [m.peers for m in one] == [2.0, 1.0, 2.0, 4.0]  # each one's nearest; 1 is nearer 0 than 2
    two = piece_rank.with_peers(found, line, count=2, radius=np.inf)
    assert [m.peers for m in two] == [3.0, 2.5, 1.5, 3.0]
    assert two[0].score == pytest.approx((1 - PEER_WEIGHT) * 1.0 + PEER_WEIGHT * 3.0)
    assert [m.own for m in two] == [1.0, 2.0, 4.0, 10.0]  # the own score is kept beside the blend


def test_a_look_alike_alone_among_its_neighbours_falls_behind_a_group_that_covers_the_piece():
    """Model 0 scores best alone; models 1-3 are a class (near each other) that all score well: with
    peers the class comes first, without them model 0 does."""
    found = [_own(0.10), _own(0.14), _own(0.15), _own(0.16), _own(0.60), _own(0.70)]
    vectors = np.array([[0.0, 9.0], [5.0, 0.0], [5.1, 0.0], [5.2, 0.0], [0.1, 9.0], [0.2, 9.1]])
    assert piece_rank.by_score(found)[0] == 0
    ranked = piece_rank.by_score(piece_rank.with_peers(found, vectors, count=2, radius=np.inf))
    assert ranked[:3] == [1, 2, 3] and ranked.index(0) == 3


def test_only_candidates_within_the_radius_are_peers():
    """By hand, on a line: models 0-2 are near each other (a class), model 3 is alone. Within a radius
    of 1, model 1's peers are 0 and 2 (0.5 and 1.0 away), model 0's and model 2's only model 1 (they
    are 1.5 apart); model 3 has none and keeps its own score, however good its far neighbours' (a source
    with no class-mates, as in a library of unique models: docs/partial.md)."""
    found = [_own(s) for s in (1.0, 2.0, 4.0, 0.5)]
    line = np.array([[0.0], [0.5], [1.5], [9.0]])
    out = piece_rank.with_peers(found, line, count=2, radius=1.0)
    assert [m.peers for m in out[:3]] == [2.0, 2.5, 2.0]
    assert np.isnan(out[3].peers) and out[3].score == 0.5
    default = piece_rank.with_peers(found, line, count=2)  # the served radius
    assert default == piece_rank.with_peers(found, line, count=2, radius=PEER_RADIUS)
    unlimited = piece_rank.with_peers(found, line, count=2, radius=np.inf)
    assert unlimited[3].peers == 3.0  # without the radius model 3 takes models 1 and 2's mean


def test_a_stored_copy_of_the_query_is_nobodys_peer():
    """Model 0 is the query itself, stored (partial distance 0): its score of about 0 stays its own, but
    it does not pull its neighbours (1, 2) ahead of model 3, which its own class-mate 4 backs."""
    found = [_own(0.0), _own(0.3), _own(0.3), _own(0.2), _own(0.25)]
    line = np.array([[0.0], [0.4], [0.5], [3.0], [3.2]])
    out = piece_rank.with_peers(found, line, count=2, radius=1.0)
    assert out[1].peers == 0.3 and out[2].peers == 0.3  # each other only, not the copy
    assert out[0].peers == 0.3  # the copy takes its peers' mean ...
    assert piece_rank.by_score(out)[:2] == [0, 3]  # ... and stays first; the source comes next
    assert COPY_DISTANCE < 1e-4  # far below a piece's distance to its own whole (2.9e-4 at the least)


def test_an_unscored_candidate_or_one_without_a_vector_is_nobodys_peer():
    found = [_own(1.0), None, _own(5.0), _own(3.0)]
    vectors = np.array([[0.0], [0.5], [np.nan], [2.0]])  # the unscored one is nearest to model 0
    out = piece_rank.with_peers(found, vectors, count=1, radius=np.inf)
    assert out[1] is None
    assert np.isnan(out[2].peers) and out[2].score == 5.0  # no vector: its own score
    assert out[0].peers == 3.0 and out[3].peers == 1.0
    lone = piece_rank.with_peers([_own(1.0), None], np.array([[0.0], [1.0]]))
    assert np.isnan(lone[0].peers) and lone[0].score == 1.0  # no fellow candidate: its own score
    with pytest.raises(ValueError):
        piece_rank.with_peers(found, vectors[:2])


def test_the_first_hit_anchors_the_order_of_the_others():
    """By hand, scores 1-4 CAPs, model 0 first. On a line, models 1, 2, 3 are 3, 5 and 1 from it (median
    3): with a first page of 1, each other one's key is its score plus anchor x CAP x distance / 3. At
    weight 1: model 1 3.0, model 2 4.67, model 3 4.33 CAPs; at weight 6: 8, 13, 6. Without vectors, or
    at weight 0: by score. A page of 2 keeps models 0 and 1 first (by score), then 3 (6) before 2 (13);
    the served page (10) is longer than these four: by score."""
    found = [_own(s * CAP) for s in (1.0, 2.0, 3.0, 4.0)]
    line = np.array([[0.0], [3.0], [5.0], [1.0]])
    assert piece_rank.by_score(found) == [0, 1, 2, 3]
    assert piece_rank.by_score(found, line, anchor=0.0, page=1) == [0, 1, 2, 3]
    assert piece_rank.by_score(found, line, anchor=1.0, page=1) == [0, 1, 3, 2]
    assert piece_rank.by_score(found, line, anchor=6.0, page=1) == [0, 3, 1, 2]
    assert piece_rank.by_score(found, line, anchor=6.0, page=2) == [0, 1, 3, 2]
    assert piece_rank.by_score(found, line, anchor=1e6, page=1)[0] == 0  # the first hit stays, at any weight
    assert len(found) <= piece_rank.PAGE and piece_rank.by_score(found, line, anchor=1e6) == [0, 1, 2, 3]
    served = piece_rank.by_score(found, line, anchor=piece_rank.ANCHOR, page=1)
    assert piece_rank.by_score(found, line, page=1) == served


def test_the_first_page_stays_in_score_order_and_the_rest_follows_the_first_hit():
    """Twelve candidates, scores 1-12 CAPs: the first PAGE (10) stay by score; of the last two, the one
    beside the first hit (model 11) comes before the far one (model 10) at a strong enough weight."""
    found = [_own((j + 1) * CAP) for j in range(12)]
    line = np.array([[0.0]] + [[5.0]] * 10 + [[0.1]])
    order = piece_rank.by_score(found, line, anchor=10.0)
    assert piece_rank.PAGE == 10
    assert order[:10] == list(range(10)) and order[10:] == [11, 10]


def test_a_stored_copy_of_the_query_stays_first_and_does_not_anchor():
    """Model 0 is the query itself, stored: it stays first (a page of 1), and the anchor is model 1,
    the best of the others. Anchored on the copy instead, model 3 (beside the copy) would come second;
    anchored on model 1 (distances 10, 1, 9.5: median 9.5), at weight 3 the keys are 2.32 and 6.0 CAPs."""
    found = [_own(0.0), _own(1.0 * CAP), _own(2.0 * CAP), _own(3.0 * CAP)]
    line = np.array([[0.0], [10.0], [11.0], [0.5]])
    assert found[0].distance <= COPY_DISTANCE < found[1].distance
    assert piece_rank.by_score(found, line, anchor=3.0, page=1) == [0, 1, 2, 3]
    no_copy = [_own(0.01 * CAP)] + found[1:]
    assert piece_rank.by_score(no_copy, line, anchor=3.0, page=1) == [0, 3, 1, 2]


def test_an_anchor_term_reads_an_unknown_vector_as_the_median_and_the_unscored_stay_last():
    vectors = np.array([[0.0], [2.0], [np.nan], [4.0]])
    term = piece_rank._anchor_term(vectors, 0, 1.0)  # distances 2, ?, 4 from model 0: median 3
    assert term == pytest.approx([0.0, CAP * 2 / 3, CAP, CAP * 4 / 3])
    assert not piece_rank._anchor_term(np.array([[np.nan], [1.0], [2.0]]), 0, 1.0).any()  # no anchor vector
    found = [_own(1.0 * CAP), None, _own(2.0 * CAP), _own(1.5 * CAP)]
    assert piece_rank.by_score(found, vectors, anchor=1.0, page=1)[-1] == 1
