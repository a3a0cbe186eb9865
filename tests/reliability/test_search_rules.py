"""The rules of app/services/search.py that no other test pinned (issue 15, item 6): a vocabulary swap
between encode and search is retried (and gives up after three), models deleted a moment ago are
skipped with ranks kept contiguous, and k is bounded on every door."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.services import search
from app.services.context import open_context
from app.services.errors import InvalidInputError, NotReadyError
from app.storage import models as models_repo


class SwappingLive:
    """A LiveIndex stand-in: the first `swaps` searches find the vocabulary changed since encode."""

    def __init__(self, ids: list[int], swaps: int) -> None:
        self.ids = np.asarray(ids, np.int64)
        self.swaps = swaps
        self.encodes = 0
        # pure-BoF vectors: the index's order is served as it is (fusion_rerank.applies)
        self.pair = SimpleNamespace(record=SimpleNamespace(id=2), params=SimpleNamespace(fusion=False))

    def encode(self, description):
        self.encodes += 1
        return 1 + self.encodes, np.zeros(4, np.float32)

    def search(self, vector, k, allowed, vocabulary_id):
        if self.swaps:
            self.swaps -= 1
            raise NotReadyError("the vocabulary changed while the query was encoded; retry")
        dist = np.arange(len(self.ids), dtype=np.float32)
        return dist, self.ids, vocabulary_id

    def search_objects(self, vector, k, allowed, vocabulary_id):  # no multi-object file here
        return np.zeros(0, np.float32), np.zeros(0, np.int64), np.zeros(0, np.int64)


@pytest.fixture
def ctx(settings):
    ctx = open_context(settings)
    with ctx.db.write() as conn:
        for i in range(5):
            mid = models_repo.insert(
                conn, name=f"m{i}", label="x", metadata={}, sha256=f"{i:064x}", file_type="obj", size_bytes=1
            )
            models_repo.set_ready(conn, mid, 10)
    return ctx


def test_a_swap_between_encode_and_search_is_encoded_again(ctx):
    live = SwappingLive([1, 2, 3], swaps=2)
    result = search.search_description(ctx, live, SimpleNamespace(local=None, input_noise=None), k=3)  # type: ignore[arg-type]
    assert live.encodes == 3 and [h.model.id for h in result.hits] == [1, 2, 3]
    assert result.vocabulary_id == 4  # the vocabulary of the last encode, not the first


def test_swaps_that_never_settle_are_a_clear_503(ctx):
    live = SwappingLive([1], swaps=10)
    with pytest.raises(NotReadyError, match="swapped"):
        search.search_description(ctx, live, SimpleNamespace(local=None, input_noise=None), k=3)  # type: ignore[arg-type]
    assert live.encodes == 3


def test_models_deleted_a_moment_ago_are_skipped_and_ranks_stay_contiguous(ctx):
    with ctx.db.write() as conn:
        models_repo.delete(conn, 2)
    live = SwappingLive([1, 2, 99, 3, 4, 5], swaps=0)  # 2: just deleted, 99: never existed
    result = search.search_description(ctx, live, SimpleNamespace(local=None, input_noise=None), k=3)  # type: ignore[arg-type]
    assert [(h.model.id, h.rank) for h in result.hits] == [(1, 1), (3, 2), (4, 3)]
    assert [h.distance for h in result.hits] == [0.0, 3.0, 4.0]


@pytest.mark.parametrize("k", [0, -1, search.MAX_K + 1, 10**6])
def test_k_out_of_range_is_refused(ctx, k):
    with pytest.raises(InvalidInputError, match=f"between 1 and {search.MAX_K}"):
        whole = SimpleNamespace(local=None, input_noise=None)
        search.search_description(ctx, SwappingLive([1], 0), whole, k=k)  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError):
        search.similar(ctx, SwappingLive([1], 0), 1, k=k)  # type: ignore[arg-type]


def test_k_at_the_bound_is_served(ctx):
    closed = SimpleNamespace(local=None, input_noise=None)
    result = search.search_description(ctx, SwappingLive([1, 2, 3], 0), closed, k=search.MAX_K)  # type: ignore[arg-type]
    assert len(result.hits) == 3
