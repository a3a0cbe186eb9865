"""The served query-adaptive re-rank (app.services.fusion_rerank): the order app.core.fusion computes,
only for fused vectors and only when on (the default); a hit's distance stays the index's L1 from the
query as sent, the re-rank's distance beside it; the asked model left out; deleted models dropped; swaps
retried."""

from __future__ import annotations

import os
from types import SimpleNamespace

import numpy as np
import pytest

from app.config import Settings
from app.core import fusion
from app.services import fusion_rerank, search
from app.services import partial as partial_mod
from app.services.context import open_context
from app.services.errors import NotReadyError
from app.services.live_index import LiveIndex
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from tests.conftest import make_settings

VOCAB_ID = 3
# fused layout [bof, 1 × dna]: class a = models 1-3, class b = models 4-6 (no two distances tie)
STORED = {1: [0.0, 0.0], 2: [0.21, 0.1], 3: [0.43, 0.2], 4: [3.0, 2.0], 5: [3.1, 2.6], 6: [3.2, 3.2]}
QUERY = np.array([2.9, 0.1], np.float32)  # BoF next to class b, Shape-DNA inside class a


class BruteLive:
    """A LiveIndex stand-in over STORED: exact L1, as the FAISS flat index answers."""

    def __init__(self, fused: bool = True, swaps: int = 0) -> None:
        scales = fusion.FusionScales(bof=1.0, dna=1.0, weight=1.0, count=1) if fused else None
        self.pair = SimpleNamespace(record=SimpleNamespace(id=VOCAB_ID), params=SimpleNamespace(fusion=fused),
                                    vocabulary=SimpleNamespace(size=1, fusion=scales))
        self.swaps = swaps
        self.searches = 0

    def require(self) -> SimpleNamespace:
        return self.pair

    def encode(self, description: object) -> tuple[int, np.ndarray]:
        return VOCAB_ID, QUERY

    def search(self, vector, k, allowed, vocabulary_id):
        self.searches += 1
        if self.swaps:
            self.swaps -= 1
            raise NotReadyError("the vocabulary changed while the query was encoded; retry")
        ids = np.array(sorted(STORED), np.int64)
        if allowed is not None:
            ids = ids[np.isin(ids, allowed)]
        d = np.array([np.abs(np.array(STORED[i], np.float32) - vector).sum() for i in ids], np.float32)
        order = np.argsort(d, kind="stable")[:k]
        return d[order], ids[order], vocabulary_id

    def search_objects(self, vector, k, allowed, vocabulary_id):  # no multi-object file here
        return np.zeros(0, np.float32), np.zeros(0, np.int64), np.zeros(0, np.int64)

    def object_vector(self, model_id, part):
        return None


@pytest.fixture
def deleted() -> set[int]:
    return set()


@pytest.fixture
def ctx(settings, monkeypatch, deleted):
    ctx = open_context(settings.model_copy(update={"fusion_rerank": True}))
    with ctx.db.write() as conn:
        for i in range(6):
            mid = models_repo.insert(conn, name=f"m{i}", label="ab"[i // 3], metadata={}, sha256=f"{i:064x}",
                                     file_type="obj", size_bytes=1)
            models_repo.set_ready(conn, mid, 10)
    def vectors_of(conn, vocabulary_id, ids):
        assert vocabulary_id == VOCAB_ID
        return {i: np.array(STORED[i], np.float32) for i in ids if i not in deleted}

    monkeypatch.setattr(fusion_rerank.vocab_repo, "vectors_of", vectors_of)
    # six models: the agreement of each part's 3 nearest (the default 10 would take every model)
    # (the ratio test off: the toy query's BoF-nearest model 4 is distinct, and the test is the class switch)
    monkeypatch.setattr(fusion_rerank, "RULE", fusion.AdaptiveRule(neighbours=3, expansion=1, distinct=0.0))
    monkeypatch.setattr(search.vocab_repo, "vector_of",
                        lambda conn, mid, vid: np.array(STORED[mid], np.float32))
    return ctx


def _expected(query: np.ndarray, leave_out: int | None = None) -> list[int]:
    ids = np.array([i for i in sorted(STORED) if i != leave_out])
    db = np.array([STORED[i] for i in ids], np.float32)

    def nearest(v, n):
        return ids[np.argsort(np.abs(db - v).sum(1), kind="stable")[:n]]

    got, _ = fusion.adaptive_rerank(query, nearest, lambda j: (j, db[np.searchsorted(ids, j)]), 1, 1.0,
                                    fusion_rerank.RULE, fusion_rerank.CANDIDATES)
    return got.tolist()


def test_a_query_is_answered_in_the_adaptive_order(ctx):
    result = search.search_description(ctx, BruteLive(), SimpleNamespace(local=None, input_noise=None), k=6)  # type: ignore[arg-type]
    got = [h.model.id for h in result.hits]
    assert got == _expected(QUERY)
    assert set(got[:3]) == {1, 2, 3}  # the Shape-DNA's class first (the fixed fusion ranks 4 first)
    assert [h.rank for h in result.hits] == [1, 2, 3, 4, 5, 6]
    assert all(a.rerank <= b.rerank for a, b in zip(result.hits, result.hits[1:], strict=False))
    # the distance is the index's, of the query as sent: L1 to the stored vector, not in the re-rank's order
    for h in result.hits:
        assert h.distance == pytest.approx(np.abs(np.array(STORED[h.model.id]) - QUERY).sum(), rel=1e-6)
    assert [h.distance for h in result.hits] != sorted(h.distance for h in result.hits)


def test_a_stored_copy_of_the_query_stays_first_at_distance_zero(ctx, monkeypatch):
    copy = np.array(STORED[5], np.float32)
    monkeypatch.setattr(BruteLive, "encode", lambda self, description: (VOCAB_ID, copy))
    result = search.search_description(ctx, BruteLive(), SimpleNamespace(local=None, input_noise=None), k=3)  # type: ignore[arg-type]
    first = result.hits[0]
    assert first.model.id == 5 and first.distance == 0.0 and first.rerank is not None


def test_off_or_pure_bof_serves_the_index_order(ctx, settings):
    fixed = BruteLive().search(QUERY, 6, None, VOCAB_ID)[1].tolist()  # the fixed fusion's order
    assert fixed[0] == 4 and fixed != _expected(QUERY)
    assert Settings().fusion_rerank is True  # on by default
    off = open_context(settings.model_copy(update={"fusion_rerank": False}))
    for c, live in ((ctx, BruteLive(fused=False)), (off, BruteLive())):
        result = search.search_description(c, live, SimpleNamespace(local=None, input_noise=None), k=6)  # type: ignore[arg-type]
        assert [h.model.id for h in result.hits] == fixed
        assert live.searches == 1 and all(h.rerank is None for h in result.hits)


def test_similar_leaves_the_model_out_of_its_candidates(ctx):
    live = BruteLive()
    result = search.similar(ctx, live, 2, k=5)  # type: ignore[arg-type]
    got = [h.model.id for h in result.hits]
    assert 2 not in got and len(got) == 5
    assert got == _expected(np.array(STORED[2], np.float32), leave_out=2)
    assert live.searches == 2  # the query's and the expanded query's


def test_k_cuts_the_reranked_list_and_deleted_models_are_dropped(ctx, deleted):
    deleted.add(1)
    result = search.search_description(ctx, BruteLive(), SimpleNamespace(local=None, input_noise=None), k=2)  # type: ignore[arg-type]
    assert len(result.hits) == 2 and 1 not in [h.model.id for h in result.hits]


def test_a_swap_during_the_rerank_is_retried(ctx):
    live = BruteLive(swaps=1)
    result = search.search_description(ctx, live, SimpleNamespace(local=None, input_noise=None), k=3)  # type: ignore[arg-type]
    assert [h.model.id for h in result.hits] == _expected(QUERY)[:3]
    live = BruteLive()
    with pytest.raises(NotReadyError, match="changed"):
        fusion_rerank.search(ctx, live, QUERY, 3, None, VOCAB_ID + 1)  # type: ignore[arg-type]


def test_the_faiss_index_and_the_database_serve_what_the_core_ranks(data_dir):
    """The seeded collection (fused vectors, FAISS flat L1): similar() with the re-rank on answers the
    order and the distances of fusion.adaptive_rerank over a brute-force copy of the stored vectors."""
    ctx = open_context(make_settings(data_dir, fusion_rerank=True))
    live = LiveIndex(ctx)
    live.refresh()
    pair = live.pair
    assert pair is not None and pair.vocabulary.fusion is not None and fusion_rerank.applies(ctx, live)
    with ctx.db.read() as conn:
        ids, vectors, _ = vocab_repo.vectors(conn, pair.record.id)
    mid = int(ids[0])
    db_ids, db = ids[1:], vectors[1:]

    def nearest(v, n):
        return db_ids[np.argsort(np.abs(db.astype(np.float64) - v).sum(1), kind="stable")[:n]]

    def vectors_of(j):
        return j, db[np.searchsorted(db_ids, j)]

    assert np.all(np.diff(db_ids) > 0)
    local = partial_mod.local_of(ctx, mid)  # the stored model's rim decides its floor (closed or open)
    noise = partial_mod.noise_of(ctx, mid)  # and its input's noise, whether a closed one is noisy
    assert local is not None and noise is not None and -1.0 <= noise <= 1.0
    want, dist = fusion.adaptive_rerank(vectors[0], nearest, vectors_of, pair.vocabulary.size,
                                        pair.vocabulary.fusion.weight, fusion_rerank.RULE,
                                        fusion_rerank.CANDIDATES, local.rim, noise)
    result = search.similar(ctx, live, mid, k=5)
    assert [h.model.id for h in result.hits] == want[:5].tolist()
    np.testing.assert_allclose([h.rerank for h in result.hits], dist[:5], rtol=1e-5)
    index_l1 = np.abs(db[np.searchsorted(db_ids, want[:5])].astype(np.float64) - vectors[0]).sum(axis=1)
    np.testing.assert_allclose([h.distance for h in result.hits], index_l1, rtol=1e-5)


@pytest.mark.parametrize(("rim", "noise"), [(0.0, 0.8), (0.1, 0.8), (0.0, -0.5)])
def test_the_querys_rim_and_noise_reach_the_rule(ctx, monkeypatch, rim, noise):
    """A whole query (rim under the piece threshold) is re-ranked with its own rim, closed (0) or open,
    and its own input noise."""
    seen: list[tuple[float | None, float | None]] = []
    real = fusion.adaptive_rerank

    def spy(*args, **kwargs):
        seen.append((args[7] if len(args) > 7 else kwargs.get("rim"),
                     args[8] if len(args) > 8 else kwargs.get("noise")))
        return real(*args, **kwargs)

    monkeypatch.setattr(fusion_rerank.fusion, "adaptive_rerank", spy)
    monkeypatch.setattr(search.partial_mod, "score", lambda ctx, local, ids, work=None: [None] * len(ids))
    query = SimpleNamespace(local=SimpleNamespace(rim=rim), input_noise=noise)
    result = search.search_description(ctx, BruteLive(), query, k=6)  # type: ignore[arg-type]
    assert seen == [(rim, noise)]
    assert not result.hits[0].partial
    ids = np.array(sorted(STORED))
    db = np.array([STORED[i] for i in ids], np.float32)
    want, _ = real(QUERY, lambda v, n: ids[np.argsort(np.abs(db - v).sum(1), kind="stable")[:n]],
                   lambda j: (j, db[np.searchsorted(ids, j)]), 1, 1.0, fusion_rerank.RULE,
                   fusion_rerank.CANDIDATES, rim, noise)
    assert [h.model.id for h in result.hits] == want.tolist()


def test_a_stored_models_rim_and_noise_come_from_one_read_of_its_description(data_dir, monkeypatch):
    """similar() weighs the stored model by its rim and its input noise: the LRU reads the description
    once for both, and again only when the file changes (a re-ingest)."""
    ctx = open_context(make_settings(data_dir, fusion_rerank=True))
    reads: list[object] = []
    real = partial_mod.load_local_and_noise

    def counting(path):
        reads.append(path)
        return real(path)

    monkeypatch.setattr(partial_mod, "load_local_and_noise", counting)
    monkeypatch.setattr(partial_mod, "_CACHE", partial_mod.LocalCache())
    live = LiveIndex(ctx)
    live.refresh()
    with ctx.db.read() as conn:
        assert live.pair is not None
        mid = int(vocab_repo.vectors(conn, live.pair.record.id)[0][0])
    local, noise = partial_mod.local_of(ctx, mid), partial_mod.noise_of(ctx, mid)
    assert local is not None and noise is not None
    search.similar(ctx, live, mid, k=3)
    assert len(reads) == 1
    path = ctx.blobs.description_path(mid)
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))  # rewritten: read again
    assert partial_mod.noise_of(ctx, mid) == noise and len(reads) == 2
