"""app.core.piece_rank: a piece's candidates, scores and order, as the service and the evaluation run them."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.config import DescribeSettings
from app.core import piece_rank
from app.core.mesh import Mesh
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
    order = np.array([5, 4, 3, 2, 1, 0])
    hits = [search_service.Hit(SimpleNamespace(id=int(i)), 0.0, r + 1) for r, i in enumerate(order)]
    served = search_service._scored(None, half, hits, len(order), True)  # type: ignore[arg-type]
    ours = piece_rank.piece_order(half, order, sigs.__getitem__, LOCAL, keep=2, coarse_keep=2)
    assert [h.model.id for h in served] == ours[: len(served)].tolist() and len(served) == 4
