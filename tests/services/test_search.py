"""search.similar and the label filter: the stored model is left out of its own answer, an unknown or
unindexed model is refused in words, a vocabulary swap is retried three times at most, and a label
narrows the candidates to its models."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.services import search
from app.services.context import open_context
from app.services.errors import ConflictError, NotFoundError, NotReadyError
from app.storage import models as models_repo

VOCAB_ID = 7


class FakeLive:
    """A LiveIndex stand-in: answers every stored id by ascending distance, after `swaps` refusals."""

    def __init__(self, ids: list[int], swaps: int = 0) -> None:
        self.ids = np.asarray(ids, np.int64)
        self.swaps = swaps
        self.calls: list[tuple[int, object, int]] = []  # (k, allowed, vocabulary_id) per search
        self.vectors: list[np.ndarray] = []
        self.objects: list[tuple[float, int, int]] = []  # object rows: (distance, model id, part)
        # pure-BoF vectors: the index's order is served as it is (fusion_rerank.applies)
        self.pair: SimpleNamespace | None = SimpleNamespace(
            record=SimpleNamespace(id=VOCAB_ID), params=SimpleNamespace(fusion=False))

    def require(self) -> SimpleNamespace:
        assert self.pair is not None
        return self.pair

    def search(self, vector, k, allowed, vocabulary_id):
        self.calls.append((k, allowed, vocabulary_id))
        self.vectors.append(vector)
        if self.swaps:
            self.swaps -= 1
            raise NotReadyError("the vocabulary changed; retry")
        ids = self.ids if allowed is None else self.ids[np.isin(self.ids, allowed)]
        ids = ids[:k]
        return np.arange(len(ids), dtype=np.float32) / 2, ids, vocabulary_id

    def search_objects(self, vector, k, allowed, vocabulary_id):
        """The object rows in `self.objects` ((distance, model id, part) each), nearest first."""
        rows = sorted(r for r in self.objects if allowed is None or r[1] in allowed)[:k]
        return (np.array([r[0] for r in rows], np.float32), np.array([r[1] for r in rows], np.int64),
                np.array([r[2] for r in rows], np.int64))


@pytest.fixture
def ctx(settings, monkeypatch):
    """Five ready models (labels a, a, b, b, b) and one queued; every ready one has a vector."""
    ctx = open_context(settings)
    with ctx.db.write() as conn:
        for i, label in enumerate(["a", "a", "b", "b", "b", "a"]):
            mid = models_repo.insert(
                conn,
                name=f"m{i}",
                label=label,
                metadata={},
                sha256=f"{i:064x}",
                file_type="obj",
                size_bytes=1,
            )
            if i < 5:
                models_repo.set_ready(conn, mid, 10)

    def vector_of(conn, model_id, vocabulary_id):
        assert vocabulary_id == VOCAB_ID and conn is not None
        return np.full(4, model_id, np.float32) if model_id <= 5 else None

    monkeypatch.setattr(search.vocab_repo, "vector_of", vector_of)
    return ctx


def test_similar_leaves_the_model_out_and_ranks_from_one(ctx):
    live = FakeLive([3, 1, 2, 4, 5])
    result = search.similar(ctx, live, 3, k=2)  # type: ignore[arg-type]
    assert [(h.model.id, h.rank) for h in result.hits] == [(1, 1), (2, 2)]
    assert [h.distance for h in result.hits] == [0.5, 1.0]
    assert result.vocabulary_id == VOCAB_ID
    assert live.calls == [(3, None, VOCAB_ID)]  # k + 1: room for the model itself
    assert live.vectors[0].tolist() == [3.0] * 4  # the stored model's own vector
    assert set(result.seconds) == {"search"} and result.seconds["search"] >= 0


def test_an_object_row_nearer_than_its_files_whole_brings_the_file_up_and_says_which_object(ctx):
    live = FakeLive([3, 1, 2, 4, 5])  # wholes at 0, 0.5, 1.0, 1.5, 2.0 (3 is the query itself)
    live.objects = [(0.25, 4, 2), (0.75, 4, 1), (0.125, 3, 1), (3.0, 5, 1)]  # 3's own object: still left out
    result = search.similar(ctx, live, 3, k=3)  # type: ignore[arg-type]
    assert [(h.model.id, h.part, h.distance) for h in result.hits] == [(4, 2, 0.25), (1, 0, 0.5), (2, 0, 1.0)]
    live = FakeLive([3, 1, 2, 4, 5])
    live.objects = [(0.25, 4, 2)]
    result = search.similar(ctx, live, 3, k=3, label="a")  # type: ignore[arg-type]
    assert [(h.model.id, h.part) for h in result.hits] == [(1, 0), (2, 0)]  # 4 is b: its rows are not allowed


def test_similar_refuses_unknown_and_unindexed_models(ctx):
    with pytest.raises(NotFoundError, match="no model with id 99"):
        search.similar(ctx, FakeLive([1]), 99, k=1)  # type: ignore[arg-type]
    with pytest.raises(ConflictError, match="model 6 is queued, not indexed"):
        search.similar(ctx, FakeLive([1]), 6, k=1)  # type: ignore[arg-type]


def test_similar_retries_a_swap_then_gives_up(ctx):
    live = FakeLive([1, 2, 3], swaps=2)
    assert [h.model.id for h in search.similar(ctx, live, 1, k=2).hits] == [2, 3]  # type: ignore[arg-type]
    assert len(live.calls) == 3
    live = FakeLive([1, 2, 3], swaps=3)
    with pytest.raises(NotReadyError, match=r"^the vocabulary is being swapped; retry$"):
        search.similar(ctx, live, 1, k=2)  # type: ignore[arg-type]
    assert len(live.calls) == 3


def test_similar_without_a_vocabulary_raises_at_once(ctx):
    live = FakeLive([1, 2], swaps=5)
    live.require = lambda: live.pair  # type: ignore[method-assign]
    original = live.search

    def search_then_drop(*args, **kwargs):
        live.pair = None  # the vocabulary went away during the search
        return original(*args, **kwargs)

    live.search = search_then_drop  # type: ignore[method-assign]
    with pytest.raises(NotReadyError, match="changed"):
        search.similar(ctx, live, 1, k=1)  # type: ignore[arg-type]
    assert len(live.calls) == 1


@pytest.mark.parametrize(("label", "expected"), [("a", [1, 2]), ("b", [3, 4, 5]), ("", None), (None, None)])
def test_a_label_narrows_the_candidates_to_its_ready_models(ctx, label, expected):
    live = FakeLive([1, 2, 3, 4, 5])
    search.similar(ctx, live, 1, k=5, label=label)  # type: ignore[arg-type]
    allowed = live.calls[0][1]
    if expected is None:
        assert allowed is None
    else:
        assert allowed.dtype == np.int64 and sorted(allowed.tolist()) == expected


class EncodingLive(FakeLive):
    """FakeLive that also encodes: records the description, returns a vector naming it."""

    def __init__(self, ids: list[int]) -> None:
        super().__init__(ids)
        self.described: list[object] = []

    def encode(self, description):
        self.described.append(description)
        return VOCAB_ID, np.full(4, 42.0, np.float32)


def test_search_description_passes_query_k_and_label_through(ctx):
    live = EncodingLive([1, 2, 3, 4, 5])
    query = SimpleNamespace(local=None, input_noise=None)  # a closed query: no local signature
    result = search.search_description(ctx, live, query, k=2, label="b")  # type: ignore[arg-type]
    assert live.described == [query]
    assert live.vectors[0].tolist() == [42.0] * 4
    k, allowed, vid = live.calls[0]
    assert k == 2 and sorted(allowed.tolist()) == [3, 4, 5] and vid == VOCAB_ID
    assert [h.model.id for h in result.hits] == [3, 4]


def test_search_description_times_encode_and_search_apart(ctx, monkeypatch):
    ticks = iter([10.0, 11.5, 20.0, 20.25, 30.0, 30.0625, 30.125])
    monkeypatch.setattr(search, "time", SimpleNamespace(perf_counter=lambda: next(ticks)))
    whole = SimpleNamespace(local=None, input_noise=None)
    result = search.search_description(ctx, EncodingLive([1]), whole, k=1)  # type: ignore[arg-type]
    # the partial stage's hit records are a step of it (a query without a signature has no other)
    assert result.seconds == {"encode": 1.5, "search": 0.25, "partial": 0.125, "partial.records": 0.0625}
    assert result.partial is None


def test_similar_times_the_whole_answer(ctx, monkeypatch):
    ticks = iter([5.0, 7.5])
    monkeypatch.setattr(search, "time", SimpleNamespace(perf_counter=lambda: next(ticks)))
    assert search.similar(ctx, FakeLive([1, 2]), 1, k=1).seconds == {"search": 2.5}  # type: ignore[arg-type]


def test_search_description_gives_up_after_three_swaps_in_words(ctx):
    live = EncodingLive([1])
    live.swaps = 3
    with pytest.raises(NotReadyError, match=r"^the vocabulary is being swapped; retry$"):
        search.search_description(ctx, live, SimpleNamespace(local=None, input_noise=None), k=1)  # type: ignore[arg-type]
    assert len(live.calls) == 3
