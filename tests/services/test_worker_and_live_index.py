"""Worker outcomes, a swap racing an ingestion, and the live index following/reconciling the database."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.core.pipeline import ShapeDescription
from app.core.vocabulary import Vocabulary
from app.index import new_index
from app.services import ingestion
from app.services import vocabularies as vocab_service
from app.services.context import open_context
from app.services.live_index import LiveIndex
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.worker.runner import Worker
from tests.conftest import make_settings


def _job(ctx, job_id):
    with ctx.db.read() as conn:
        return jobs_repo.get(conn, job_id)


def test_invalid_mesh_fails_at_once_and_transient_errors_retry(tmp_path, monkeypatch, corpus):
    ctx = open_context(make_settings(tmp_path / "d", max_attempts=2))
    bad = ingestion.submit(ctx, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "tri.obj")
    Worker(ctx, "w").run_once()
    job = _job(ctx, bad.job_id)
    assert job.state == "failed" and job.attempts == 1 and job.error
    # a fault that might pass (here: always) is retried until attempts run out
    path, _ = corpus.seeded[0]
    sub = ingestion.submit(ctx, path.read_bytes(), path.name)

    def boom(*a, **k):
        raise OSError("disk hiccup")

    monkeypatch.setattr(ingestion, "describe_and_view", boom)
    Worker(ctx, "w").run_once()
    assert _job(ctx, sub.job_id).state == "queued" and "disk hiccup" in _job(ctx, sub.job_id).error
    Worker(ctx, "w").run_once()
    job = _job(ctx, sub.job_id)
    assert job.state == "failed" and "gave up after 2 attempts" in job.error
    with ctx.db.read() as conn:
        assert models_repo.get(conn, sub.model.id).status == "failed"
    assert ctx.blobs.mesh_path(sub.model.sha256, "obj").is_file()  # the upload stays on disk


def test_ingestion_racing_a_swap_ends_encoded_with_the_new_vocabulary(data_dir, corpus, monkeypatch):
    ctx = open_context(make_settings(data_dir))
    with ctx.db.read() as conn:
        old = vocab_repo.active(conn)
    rng = np.random.default_rng(0)
    replacement = Vocabulary.fit_features(rng.random((200, 4)), size=8, run="run5")
    new_id = vocab_service.register(ctx, replacement, activate=False)
    path, _ = corpus.held_out[2]
    sub = ingestion.submit(ctx, path.read_bytes(), path.name)
    real = ingestion.load_vocabulary
    calls = []

    def swap_after_encode(c, record):
        calls.append(record.id)
        if len(calls) == 1:  # the swap lands between this encode and the commit
            with ctx.db.write() as conn:
                vocab_repo.activate(conn, new_id)
        return real(c, record)

    monkeypatch.setattr(ingestion, "load_vocabulary", swap_after_encode)
    Worker(ctx, "w").run_once()
    assert calls == [old.id, new_id]
    with ctx.db.read() as conn:
        assert vocab_repo.vector_of(conn, sub.model.id, new_id) is not None
        assert vocab_repo.vector_of(conn, sub.model.id, old.id) is None
    assert _job(ctx, sub.job_id).state == "done"


def test_a_fresh_data_directory_creates_its_empty_index_without_a_warning(tmp_path, caplog):
    from app.config import SHIPPED_VOCABULARY

    ctx = open_context(make_settings(tmp_path / "fresh", default_vocabulary=SHIPPED_VOCABULARY))
    vocab_service.ensure_default(ctx)
    live = LiveIndex(ctx)
    with caplog.at_level("INFO", logger="app.services.live_index"):
        live.refresh()
    assert live.pair is not None and live.pair.reconciled == "created" and live.pair.index.count == 0
    assert ctx.index_path(live.pair.record.id).exists()  # saved: the next start loads it
    ours = [r for r in caplog.records if r.name == "app.services.live_index"]
    assert ours and not [r for r in ours if r.levelno >= 30], [r.getMessage() for r in ours]
    again = LiveIndex(ctx)
    again.refresh()
    assert again.pair.reconciled == "loaded"


def test_a_lost_index_file_with_stored_vectors_is_rebuilt_with_a_warning(data_dir, caplog):
    ctx = open_context(make_settings(data_dir))
    first = LiveIndex(ctx)
    first.refresh()
    n = first.pair.index.count
    path = ctx.index_path(first.pair.record.id)
    path.unlink()
    live = LiveIndex(ctx)
    with caplog.at_level("INFO", logger="app.services.live_index"):
        live.refresh()
    assert n > 0 and live.pair.index.count == n and live.pair.reconciled.startswith("rebuilt: no index file")
    ours = [r for r in caplog.records if r.name == "app.services.live_index"]
    warned = [r.getMessage() for r in ours if r.levelno == 30]
    assert any("rebuilt from stored vectors" in m for m in warned), warned


def test_live_index_follows_new_vectors_and_rebuilds_a_disagreeing_file(data_dir):
    ctx = open_context(make_settings(data_dir))
    live = LiveIndex(ctx)
    live.refresh()
    pair = live.pair
    n = pair.index.count
    assert pair.reconciled in ("loaded", "rebuilt: no index file at " + str(ctx.index_path(pair.record.id)))
    ids = pair.index.ids()
    dim = pair.index.dim  # words + Shape-DNA: the rebuild stored fusion scales
    assert dim == pair.vocabulary.dimension(ctx.settings.encode.params()) > pair.vocabulary.size
    # a re-encoded vector (new seq) replaces the old one in the live index
    with ctx.db.write() as conn:
        vocab_repo.put_vector(conn, int(ids[0]), pair.record.id, np.eye(dim)[0])
    assert live.refresh() == 1 and live.pair.index.count == n
    dist, got, _ = live.search(np.eye(dim, dtype=np.float32)[0], 1)
    assert got[0] == ids[0] and dist[0] == pytest.approx(0.0)
    live.remove([int(ids[0])])
    assert live.pair.index.count == n - 1
    assert live.refresh() == 0  # a deleted id is not brought back by a late poll
    live.save()
    # a file that disagrees with the database (one id missing) is rebuilt on load
    stale = new_index(ctx.settings.index_backend, dim)
    with ctx.db.read() as conn:
        all_ids, vectors, _ = vocab_repo.vectors(conn, pair.record.id)
    stale.add(all_ids[1:], vectors[1:])
    stale.save(ctx.index_path(pair.record.id))
    fresh = LiveIndex(ctx)
    fresh.refresh()
    assert fresh.pair.reconciled.startswith("rebuilt")
    np.testing.assert_array_equal(fresh.pair.index.ids(), np.sort(all_ids))


def test_flipping_fusion_re_encodes_the_stored_vectors_on_load(data_dir):
    from app.config import EncodeSettings

    ctx = open_context(make_settings(data_dir))
    fused = LiveIndex(ctx)
    fused.refresh()
    pair = fused.pair
    words, ids = pair.vocabulary.size, pair.index.ids()
    assert pair.vocabulary.fusion is not None and pair.index.dim > words
    plain_ctx = open_context(make_settings(data_dir, encode=EncodeSettings(fusion=False)))
    plain = LiveIndex(plain_ctx)
    plain.refresh()  # stored vectors are fused, the settings want pure BoF: re-encoded, index rebuilt
    assert plain.pair.index.dim == words and plain.pair.reconciled.startswith("rebuilt: dimension")
    np.testing.assert_array_equal(plain.pair.index.ids(), ids)
    with ctx.db.read() as conn:
        _, vectors, _ = vocab_repo.vectors(conn, pair.record.id)
    assert vectors.shape == (len(ids), words)
    # each model's nearest neighbour is itself, at distance 0, in the pure-BoF index as well
    dist, got, _ = plain.search(vectors[0], 1)
    assert dist[0] == pytest.approx(0.0)
    fresh = LiveIndex(ctx)  # and back: fused again
    fresh.refresh()
    assert fresh.pair.index.dim == pair.index.dim


def test_a_version_keeps_the_encoding_it_was_registered_with(data_dir, caplog):
    """Hard and soft BoFs have the same length: a version records its encoding when it is registered,
    and every vector of it (stored, re-encoded or queried) is made that way whatever SHAPEBAG_ENCODE__MODE
    a process starts with, so soft queries never meet hard vectors; new settings apply from the next
    vocabulary rebuild, and the service says so."""
    from app.config import EncodeSettings

    soft_ctx = open_context(make_settings(data_dir))
    soft = LiveIndex(soft_ctx)
    soft.refresh()
    vid = soft.pair.record.id
    with soft_ctx.db.read() as conn:
        assert vocab_repo.get(conn, vid).metadata["vectors_encoding"]["mode"] == "soft"
        ids, stored, _ = vocab_repo.vectors(conn, vid)
    soft.save()
    vocab_service._cache.clear()  # a fresh process
    hard_ctx = open_context(make_settings(data_dir, encode=EncodeSettings(mode="hard")))
    hard = LiveIndex(hard_ctx)
    with caplog.at_level("WARNING", logger="app.services.vocabularies"):
        hard.refresh()
    assert hard.pair.params.mode == "soft" and hard.pair.reconciled == "loaded"
    assert any("apply from the next vocabulary rebuild" in r.getMessage() for r in caplog.records)
    # a model described again and encoded by the hard-configured process lands on its stored vector
    description = ShapeDescription.load(hard_ctx.blobs.description_path(int(ids[0])))
    got_vid, vector = hard.encode(description)
    assert got_vid == vid and np.allclose(vector, stored[0], atol=1e-6)
    dist, got, _ = hard.search(vector, 1)
    assert got[0] == ids[0] and dist[0] == pytest.approx(0.0, abs=1e-5)
    # re-encoding (the admin index rebuild) keeps the version's encoding too
    assert vocab_service.reencode_version(hard_ctx, hard.pair.record) == len(ids)
    with hard_ctx.db.read() as conn:
        _, again, _ = vocab_repo.vectors(conn, vid)
    np.testing.assert_allclose(again[np.argsort(ids)], stored[np.argsort(ids)], atol=1e-6)


def test_a_worker_with_other_settings_ingests_with_the_version_s_encoding(data_dir, corpus):
    from app.config import EncodeSettings
    from app.core.vocabulary import EncodeParams

    ctx = open_context(make_settings(data_dir, encode=EncodeSettings(mode="hard")))
    path, label = corpus.held_out[0]
    model_id = ingestion.submit(ctx, path.read_bytes(), path.name, name="late", label=label).model.id
    Worker(ctx, "hard-configured").run_forever(exit_when_idle=True)
    with ctx.db.read() as conn:
        record = vocab_repo.active(conn)
        stored = vocab_repo.vector_of(conn, model_id, record.id)
    vocab = vocab_service.load_vocabulary(ctx, record)
    description = ShapeDescription.load(ctx.blobs.description_path(model_id))
    assert np.allclose(stored, vocab.encode(description, EncodeParams(mode="soft")), atol=1e-6)
    assert not np.allclose(stored, vocab.encode(description, EncodeParams(mode="hard")), atol=1e-3)


def test_a_version_without_a_record_encodes_as_its_fusion_scale_was_fit(data_dir):
    """Data directories from before versions recorded their encoding: the vocabulary's fit encoding
    (the service's when it was registered) stands in; a version older than both follows the settings."""
    from app.config import EncodeSettings

    ctx = open_context(make_settings(data_dir, encode=EncodeSettings(mode="hard")))
    with ctx.db.write() as conn:  # as an older release left it: no "vectors_encoding"
        record = vocab_repo.active(conn)
        meta = {k: v for k, v in record.metadata.items() if k != "vectors_encoding"}
        conn.execute("UPDATE vocabularies SET metadata = ? WHERE id = ?", (json.dumps(meta), record.id))
        record = vocab_repo.active(conn)
    vocab = vocab_service.load_vocabulary(ctx, record)
    assert vocab.metadata["encode"]["mode"] == "soft"  # the seed's vocabulary was fit with soft BoFs
    assert vocab_service.stored_encoding(record, vocab) == vocab.metadata["encode"]
    assert vocab_service.version_params(ctx, record, vocab).mode == "soft"
    older = Vocabulary(vocab.centers, run=vocab.run, sigma=vocab.sigma)  # no "encode" either
    assert vocab_service.stored_encoding(record, older) is None
    assert vocab_service.version_params(ctx, record, older).mode == "hard"


def test_flipping_fusion_with_a_description_missing_drops_that_model_s_old_vector(data_dir, caplog):
    """A model whose cached description is gone cannot be re-encoded; its old vector (another length)
    must not stay beside the new ones, or no index could be built from them."""
    from app.config import EncodeSettings

    ctx = open_context(make_settings(data_dir))
    with ctx.db.read() as conn:
        ids = models_repo.ready_ids(conn)
    ctx.blobs.description_path(ids[0]).unlink()
    plain = LiveIndex(open_context(make_settings(data_dir, encode=EncodeSettings(fusion=False))))
    with caplog.at_level("WARNING", logger="app.services.vocabularies"):
        plain.refresh()
    assert plain.pair.index.dim == plain.pair.vocabulary.size
    assert sorted(plain.pair.index.ids().tolist()) == sorted(ids[1:])
    assert any(f"without a cached description leave version {plain.pair.record.id}" in r.getMessage()
               and str(ids[0]) in r.getMessage() for r in caplog.records)


def test_similar_racing_a_swap_reads_the_vector_again(data_dir, monkeypatch):
    from app.services import search

    ctx = open_context(make_settings(data_dir))
    live = LiveIndex(ctx)
    live.refresh()
    old = live.pair.record.id
    ids = live.pair.index.ids()
    replacement = Vocabulary.fit_features(np.random.default_rng(0).random((200, 4)), size=8, run="run5")
    new_id = vocab_service.register(ctx, replacement, activate=False)
    with ctx.db.write() as conn:  # every model already encoded with the new vocabulary, as a rebuild does
        for i, model_id in enumerate(ids):
            vocab_repo.put_vector(conn, int(model_id), new_id, np.eye(8)[i % 8])
    real = vocab_repo.vector_of
    reads = []

    def swap_after_read(conn, model_id, vocabulary_id):
        reads.append(vocabulary_id)
        vector = real(conn, model_id, vocabulary_id)
        if len(reads) == 1:  # the swap lands between reading the old vector and searching
            with ctx.db.write() as w:
                vocab_repo.activate(w, new_id)
            live.refresh()
        return vector

    monkeypatch.setattr(vocab_repo, "vector_of", swap_after_read)
    result = search.similar(ctx, live, int(ids[0]), k=3)
    assert reads == [old, new_id]
    assert result.vocabulary_id == new_id and len(result.hits) == 3
