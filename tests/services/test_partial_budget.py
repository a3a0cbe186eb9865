"""The partial scoring's own deadline (app.services.partial.score): past it, candidates stay unscored."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.core.partial import LocalSignature
from app.services import partial


@pytest.fixture
def scored(monkeypatch):
    """score() over 50 candidates with a fake signature store and matcher; returns a runner."""
    calls: list[int] = []
    monkeypatch.setattr(partial._CACHE, "get", lambda path: None if path == "no-sig-7" else f"sig-{path}")

    def fake_match(query, models, params, mutual=False):
        assert mutual == (partial.MUTUAL > 0)  # the mutual share only when the score reads it
        calls.append(len(models))
        return [f"match-{m}" for m in models]

    monkeypatch.setattr(partial, "match_many", fake_match)
    monkeypatch.setattr(partial.piece_rank, "voted", lambda query, found, params: found)  # fakes: no samples
    ctx = SimpleNamespace(blobs=SimpleNamespace(description_path=lambda i: f"no-sig-{i}" if i == 7 else i))

    def run(budget_s: float, work: partial.Work | None = None) -> tuple[list, list[int]]:
        monkeypatch.setattr(partial, "SCORE_BUDGET_S", budget_s)
        calls.clear()
        return partial.score(ctx, object(), list(range(50)), work), list(calls)

    return run


def test_within_the_budget_every_candidate_with_a_signature_is_scored(scored):
    work = partial.Work()
    out, calls = scored(60.0, work)
    assert sum(calls) == 49 and len(calls) == 4  # chunks of 16, one candidate without a signature
    assert out[7] is None and out[0] == "match-sig-0" and out[49] == "match-sig-49"
    # every candidate reached (the one without a signature too: it has nothing to score)
    assert (work.scored, work.scored_of, work.score_cut) == (50, 50, False)
    assert set(work.seconds) == {"score", "vote"}


def test_past_the_deadline_only_the_first_chunk_is_scored_and_in_place(scored):
    work = partial.Work()
    out, calls = scored(0.0, work)
    assert calls == [partial.CHUNK - 1]  # the first chunk always runs (candidate 7 has no signature)
    assert out[: partial.CHUNK] == [None if j == 7 else f"match-sig-{j}" for j in range(partial.CHUNK)]
    assert out[partial.CHUNK:] == [None] * (50 - partial.CHUNK)
    assert (work.scored, work.scored_of, work.score_cut) == (partial.CHUNK, 50, True)


def test_a_query_without_a_signature_scores_nothing(scored):
    assert partial.score(SimpleNamespace(), None, [1, 2]) == [None, None]


def test_candidates_are_the_global_head_and_the_coarse_nearest_in_global_order(monkeypatch):
    """300 models in global order; the coarse distance (a fake matcher) prefers the last ones: the
    candidates are the first GLOBAL_KEEP and the COARSE_KEEP coarse nearest, read on the query's head."""
    heads: list[int] = []
    monkeypatch.setattr(partial._CACHE, "get", lambda path: path)

    def fake_match(query, models, params, mutual=False):
        assert not mutual  # the coarse pass ranks by the distance: no extra product
        heads.append(len(query.slopes))
        return [SimpleNamespace(distance=float(-m)) for m in models]  # model id m: larger is nearer

    monkeypatch.setattr(partial, "match_many", fake_match)
    monkeypatch.setattr(partial, "GLOBAL_KEEP", 10)
    monkeypatch.setattr(partial, "COARSE_KEEP", 5)
    ctx = SimpleNamespace(blobs=SimpleNamespace(description_path=lambda i: i))
    query = LocalSignature(slopes=np.zeros((256, 21), np.float32), area=np.full(256, 1 / 256, np.float32),
                           valid=np.full(256, 21, np.int16), rim=1.0)
    ids = list(range(1000, 1300))
    work = partial.Work()
    got = partial.candidates(ctx, query, ids, work)
    assert got == [*range(10), *range(295, 300)]
    assert set(heads) == {partial.COARSE_POINTS}
    assert (work.coarse_read, work.coarse_of, work.coarse_cut) == (300, 300, False)
    # a collection no larger than the global head needs no coarse pass; a query without a signature none
    heads.clear()
    assert partial.candidates(ctx, query, ids[:10]) == list(range(10)) and heads == []
    assert partial.candidates(ctx, None, ids) == list(range(10))


def test_the_scored_candidates_carry_their_vote_among_the_scored_ones(monkeypatch):
    """Real matches: each query sample votes for its VOTE_TOP nearest scored candidates; one without a
    signature is unscored and takes no vote. Candidate 3 equals the query: every sample votes for it."""
    from app.core.partial_match import VOTE_TOP
    from app.core.pipeline import LOCAL

    rng = np.random.default_rng(0)
    width = LOCAL.slopes + LOCAL.shifts - 1
    query = LocalSignature(slopes=rng.normal(size=(20, width)).astype(np.float32),
                           area=np.full(20, 0.05, np.float32), valid=np.full(20, width, np.int16), rim=1.0)
    sigs = {i: LocalSignature(slopes=rng.normal(size=(20, LOCAL.slopes)).astype(np.float32),
                              area=np.full(20, 0.05, np.float32), valid=np.full(20, LOCAL.slopes, np.int16),
                              rim=0.0) for i in range(VOTE_TOP + 5)}
    sigs[3] = LocalSignature(slopes=query.slopes[:, :LOCAL.slopes].copy(), area=query.area,
                             valid=np.full(20, LOCAL.slopes, np.int16), rim=0.0)
    del sigs[5]
    monkeypatch.setattr(partial._CACHE, "get", lambda path: sigs.get(path))
    ctx = SimpleNamespace(blobs=SimpleNamespace(description_path=lambda i: i))
    found = partial.score(ctx, query, list(range(VOTE_TOP + 5)))
    assert found[5] is None
    assert found[3] is not None and found[3].vote == pytest.approx(1.0)
    shares = [m.vote for m in found if m is not None]
    assert sum(shares) == pytest.approx(VOTE_TOP)  # each sample's unit of area goes to VOTE_TOP models
    assert min(found, key=lambda m: m.score if m is not None else np.inf) is found[3]


def test_past_its_deadline_the_coarse_pass_reports_what_it_read(monkeypatch):
    """The coarse pass stops at COARSE_BUDGET_S after its first chunk: the models not read are no
    candidates, and the Work says how many were read of how many."""
    monkeypatch.setattr(partial._CACHE, "get", lambda path: path)
    monkeypatch.setattr(partial, "match_many",
                        lambda query, models, params, mutual=False: [SimpleNamespace(distance=float(-m))
                                                                     for m in models])
    monkeypatch.setattr(partial, "GLOBAL_KEEP", 10)
    monkeypatch.setattr(partial, "COARSE_KEEP", 5)
    monkeypatch.setattr(partial, "COARSE_BUDGET_S", 0.0)
    ctx = SimpleNamespace(blobs=SimpleNamespace(description_path=lambda i: i))
    query = LocalSignature(slopes=np.zeros((256, 21), np.float32), area=np.full(256, 1 / 256, np.float32),
                           valid=np.full(256, 21, np.int16), rim=1.0)
    work = partial.Work()
    got = partial.candidates(ctx, query, list(range(300)), work)
    assert (work.coarse_read, work.coarse_of, work.coarse_cut) == (partial.CHUNK, 300, True)
    assert got == [*range(10), *range(11, partial.CHUNK)]  # the coarse nearest among the models read
    assert "coarse" in work.seconds
