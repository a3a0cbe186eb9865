"""Vocabulary versions: register the shipped default, load, rebuild (fit -> encode -> index -> swap)."""

from __future__ import annotations

import logging
import shutil
import sqlite3
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from app.core.fusion import DEFAULT_WEIGHT
from app.core.pipeline import DescribeParams, ShapeDescription
from app.core.vocabulary import EncodeParams, Vocabulary
from app.index import new_index
from app.services import object_rows
from app.services.context import ServiceContext
from app.services.errors import InvalidInputError
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import objects as objects_repo
from app.storage import vocabularies as vocab_repo
from app.storage.vocabularies import VocabularyRecord

log = logging.getLogger(__name__)
_cache: dict[tuple[str, int], Vocabulary] = {}
_cache_lock = threading.Lock()


def load_vocabulary(ctx: ServiceContext, record: VocabularyRecord) -> Vocabulary:
    """Vocabulary of a version (versions are immutable, so a per-process cache is safe)."""
    key = (str(ctx.data_dir), record.id)
    with _cache_lock:
        if key not in _cache:
            vocab = Vocabulary.load(ctx.blobs.local_dir(inside_data_dir(ctx, record.path)))
            params = version_params(ctx, record, vocab)
            _warn_if_encoded_otherwise(vocab, params, record.id)
            _warn_if_settings_wait(ctx.settings.encode.params(), params, record.id)
            _warn_if_described_otherwise(vocab, ctx.settings.describe.params(), record.id)
            _cache[key] = vocab
        return _cache[key]


def _warn_if_encoded_otherwise(vocab: Vocabulary, params: EncodeParams, version: int) -> None:
    """The fusion BoF scale was fit on BoFs encoded one way; other encode settings still rank, but the
    BoF and Shape-DNA parts are then weighted a little off (area vs count: ~4 % on the shipped one)."""
    changes = vocab.fusion_encoding_changes(params)
    if changes:
        log.warning("vocabulary version %d's fusion scale was fit with %s; its vectors are encoded with %s: "
                    "rebuild the vocabulary (POST /admin/vocabulary/rebuild) to refit it", version,
                    *_fit_and_now(changes))


def _warn_if_settings_wait(settings: EncodeParams, version: EncodeParams, version_id: int) -> None:
    """Say when SHAPEBAG_ENCODE__* ask for another quantisation or weighting than a version encodes with."""
    now, kept = settings.encoding(), version.encoding()
    if now != kept:
        log.warning("vocabulary version %d encodes with %s, the encode settings say %s: they apply from the "
                    "next vocabulary rebuild (POST /admin/vocabulary/rebuild)", version_id, kept, now)


def _warn_if_described_otherwise(vocab: Vocabulary, params: DescribeParams, version: int) -> None:
    """Say when a version's words were fit on descriptions made with other describe parameters than
    this process makes (an upgrade that changed the describe defaults, or changed SHAPEBAG_DESCRIBE__*):
    the models stored before keep their old descriptions, so new uploads and queries are compared with
    shapes described another way until the models are re-ingested."""
    changes = vocab.describe_changes(params)
    if changes:
        log.warning("vocabulary version %d was fit on descriptions made with %s; this process describes "
                    "with %s: models ingested before the change keep their old descriptions, so re-ingest "
                    "them and rebuild the vocabulary (POST /admin/vocabulary/rebuild), or set those "
                    "SHAPEBAG_DESCRIBE__* values back", version, *_fit_and_now(changes))


def _fit_and_now(changes: dict) -> tuple[dict, dict]:
    """{setting: (fit, now)} -> ({setting: fit}, {setting: now}), the two sides a warning names."""
    return {k: fit for k, (fit, _) in changes.items()}, {k: now for k, (_, now) in changes.items()}


def stored_encoding(record: VocabularyRecord, vocab: Vocabulary) -> dict | None:
    """How the vectors of version `record` are encoded: as recorded when it was registered or, for a
    version registered before that was recorded, as its fusion scale was fit (the service's encoding
    then); None when neither says (a version older than both)."""
    recorded = record.metadata.get("vectors_encoding")
    if isinstance(recorded, dict):
        return recorded
    fitted = vocab.metadata.get("encode")
    return fitted if isinstance(fitted, dict) else None


def version_params(ctx: ServiceContext, record: VocabularyRecord, vocab: Vocabulary) -> EncodeParams:
    """EncodeParams for every vector of version `record`, stored or queried: the quantisation and
    weighting (mode, σ, scope, area) the version was registered with, so that one version never holds
    vectors made two ways (and its fusion scale stays the one fit for them); the rest (fusion on or
    off) from this process's settings. New encode settings apply from the next vocabulary rebuild."""
    stored = stored_encoding(record, vocab)
    params = ctx.settings.encode.params()
    return params if stored is None else params.with_encoding(stored)


def inside_data_dir(ctx: ServiceContext, relative: str) -> Path:
    """data_dir / relative, refusing anything that resolves outside the data directory."""
    root = ctx.data_dir.resolve()
    path = (root / relative).resolve()
    if not relative or not path.is_relative_to(root):
        raise ValueError(f"refusing to read {relative!r}: vocabulary files live inside the data directory")
    return path


def register(ctx: ServiceContext, vocab: Vocabulary, activate: bool, collection_models: int = 0) -> int:
    """Save `vocab` as a new version (files first, then the row); returns its id.

    collection_models: how many ready models the collection held when it was fit on it (0: fit
    elsewhere, such as the shipped one); the background refit (services/refit.py) counts the
    collection's doublings from it."""
    with ctx.db.write() as conn:
        vid = vocab_repo.insert(
            conn,
            path="",
            trained_on=int(vocab.metadata.get("trained_on_descriptors", 0)),
            size=vocab.size,
            run=vocab.run,
            # how every vector of this version will be encoded (version_params reads it back)
            metadata=dict(
                vocab.describe_meta(), vectors_encoding=ctx.settings.encode.params().encoding(),
                **({"collection_models": collection_models} if collection_models else {}),
            ),
            created_at=vocab.metadata.get("created_at"),
        )
        directory = ctx.vocabulary_dir(vid)
        if directory.exists():  # debris of a process killed after its save, before its commit: no row uses it
            log.warning("removing %s, left by an interrupted vocabulary rebuild", directory)
            shutil.rmtree(directory)
        vocab.save(directory)
        ctx.blobs.share_dir(directory, conn)  # database blob backend: other hosts load it from there
        vocab_repo.set_path(conn, vid, str(directory.relative_to(ctx.data_dir)))
        if activate:
            vocab_repo.activate(conn, vid)
    return vid


def ensure_default(ctx: ServiceContext) -> int | None:
    """With no vocabulary version yet, register and activate the shipped default (if there is one)."""
    path = ctx.settings.default_vocabulary
    with ctx.db.read() as conn:
        if vocab_repo.all_versions(conn):
            return None
    if path is None or not (Path(path) / "vocabulary.json").is_file():
        log.warning("no vocabulary: none shipped at %s; fit one with POST /admin/vocabulary/rebuild", path)
        return None
    vocab = Vocabulary.load(path)
    with ctx.db.write() as conn:  # re-check under the write lock: another process may have won
        if vocab_repo.all_versions(conn):
            return None
    vid = register(ctx, vocab, activate=True)
    log.info("registered the shipped vocabulary %s as version %d", path, vid)
    return vid


def load_descriptions(ctx: ServiceContext, model_ids: list[int]) -> tuple[list[int], list[ShapeDescription]]:
    """Cached descriptions of `model_ids` (models whose file is gone are skipped)."""
    ids, descs = [], []
    for mid in model_ids:
        path = ctx.blobs.description_path(mid)
        if path.is_file():
            ids.append(mid)
            descs.append(ShapeDescription.load(path))
        else:
            log.warning("model %d is ready but its description %s is missing", mid, path)
    return ids, descs


def encode_all(vocab: Vocabulary, descs: list[ShapeDescription], params: EncodeParams) -> np.ndarray:
    """(n, vocab.dimension(params)) float32 vectors: BoF, or BoF + Shape-DNA when fused."""
    if not descs:
        return np.zeros((0, vocab.dimension(params)), np.float32)
    return np.stack([vocab.encode(d, params) for d in descs])


def fit_vocabulary(
    ctx: ServiceContext, descs: list[ShapeDescription], size: int, run: str, seed: int,
    fusion_weight: float = DEFAULT_WEIGHT, metadata: dict | None = None,
) -> Vocabulary:
    """k-means words on `descs`, plus the fusion scales of the same shapes (BoF under the service's
    encode settings, and Shape-DNA): fixed now, so every vector of this version stays comparable."""
    vocab = Vocabulary.fit(descs, size=size, run=run, seed=seed, metadata=metadata)
    try:
        return vocab.with_fusion(descs, ctx.settings.encode.params(), fusion_weight)
    except ValueError as exc:  # one training shape, or spectra too short: the BoF alone still serves
        log.warning("vocabulary without fusion scales (pure BoF): %s", exc)
        return vocab


def rebuild_vocabulary(
    ctx: ServiceContext, job_id: int, payload: dict, keep_alive: Callable[[], None] = lambda: None
) -> dict:
    """Fit a new vocabulary on the stored descriptions, encode every model, build its index, swap.

    Queries keep using the old pair until the swap; models that became ready meanwhile are encoded
    with the new vocabulary right after it (encode_missing).
    """
    timings: dict[str, float] = {}
    t = time.perf_counter()
    size = int(payload.get("size") or ctx.settings.vocabulary_size)
    run = str(payload.get("run") or ctx.settings.vocabulary_run)
    seed = int(payload.get("seed") or 0)
    weight = payload.get("fusion_weight")
    weight = DEFAULT_WEIGHT if weight is None else float(weight)
    with ctx.db.read() as conn:
        ids = models_repo.ready_ids(conn)
    collection = len(ids)  # the refit's doublings count from this, even if some descriptions are missing
    ids, descs = load_descriptions(ctx, ids)
    if not descs:
        raise InvalidInputError("no ready models to fit a vocabulary on: ingest some first")
    timings["load_descriptions"] = time.perf_counter() - t
    keep_alive()
    t = time.perf_counter()
    vocab = fit_vocabulary(ctx, descs, size, run, seed, weight, metadata={"models": len(descs)})
    timings["fit"] = time.perf_counter() - t
    keep_alive()
    t = time.perf_counter()
    vid = register(ctx, vocab, activate=False, collection_models=collection)
    params = ctx.settings.encode.params()  # what register() recorded as the new version's encoding
    vectors = encode_all(vocab, descs, params)
    index = new_index(ctx.settings.index_backend, vocab.dimension(params))
    index.add(np.asarray(ids, np.int64), vectors)
    index.save(ctx.index_path(vid))
    timings["encode_and_index"] = time.perf_counter() - t
    keep_alive()
    part_rows = object_rows.encode_parts(ctx, vocab, params, _parts_of(ctx, ids))  # a plate's objects
    keep_alive()
    with ctx.db.write() as conn:  # the swap: vectors + active flag in ONE transaction
        alive = set(models_repo.get_many(conn, ids))
        for mid, vec in zip(ids, vectors, strict=True):
            if mid in alive:  # deleted during the rebuild: skip
                vocab_repo.put_vector(conn, mid, vid, vec)
        object_rows.store_vectors(conn, vid, part_rows)
        replaced = vocab_repo.active(conn)
        vocab_repo.activate(conn, vid)
        stale = stale_versions(vocab_repo.all_versions(conn), vid, replaced)
        pruned = vocab_repo.delete_inactive(conn, stale)
    remove_version_files(ctx, pruned)
    timings["pruned_versions"] = float(len(pruned))
    timings["encoded_after_swap"] = float(len(encode_missing(ctx, vid)))
    with ctx.db.write() as conn:
        jobs_repo.mark_done(conn, job_id, dict(timings, vocabulary_id=vid, models=len(ids)))
    log.info("vocabulary version %d active (%d words, %d models)", vid, vocab.size, len(ids))
    return timings


def stale_versions(
    versions: list[VocabularyRecord], new_id: int, replaced: VocabularyRecord | None
) -> list[int]:
    """Versions a swap to `new_id` leaves unused: all but the new one and the one it replaced.

    The replaced version stays one more round: the API process serves it until its next poll, and a
    request pinned to it must still find its vectors. Older versions are served by nobody, and a
    version whose rebuild was killed before its swap (inactive, never served) goes with them.
    """
    keep = {new_id} | ({replaced.id} if replaced is not None else set())
    return [v.id for v in versions if v.id not in keep and v.id < new_id]  # > new_id: not ours to judge


def remove_version_files(ctx: ServiceContext, vocabulary_ids: list[int]) -> None:
    """Delete the directories of deleted versions (after the commit: a crash leaves files, not rows)."""
    for vid in vocabulary_ids:
        shutil.rmtree(ctx.vocabulary_dir(vid), ignore_errors=True)
        ctx.blobs.forget_dir(ctx.vocabulary_dir(vid))
    if vocabulary_ids:
        log.info("pruned vocabulary versions %s", ", ".join(map(str, vocabulary_ids)))


def encode_missing(ctx: ServiceContext, vocabulary_id: int) -> list[int]:
    """Encode ready models that have no BoF for this version yet (and object rows without one);
    returns the models' ids."""
    with ctx.db.read() as conn:
        record = vocab_repo.get(conn, vocabulary_id)
        missing = vocab_repo.ready_without_vector(conn, vocabulary_id)
        parts = objects_repo.parts_without_vector(conn, vocabulary_id) if record is not None else []
    if record is None or not (missing or parts):
        return []
    vocab = load_vocabulary(ctx, record)
    params = version_params(ctx, record, vocab)
    ids, descs = load_descriptions(ctx, missing)
    vectors = encode_all(vocab, descs, params)
    part_rows = object_rows.encode_parts(ctx, vocab, params, parts)
    with ctx.db.write() as conn:
        alive = set(models_repo.get_many(conn, ids))
        for mid, vec in zip(ids, vectors, strict=True):
            if mid in alive:
                vocab_repo.put_vector(conn, mid, vocabulary_id, vec)
        object_rows.store_vectors(conn, vocabulary_id, part_rows)
    return ids


def reencode_active(ctx: ServiceContext, job_id: int) -> dict:
    """rebuild_index job: re-encode every ready model with the active vocabulary from its description.

    The API process sees the new rows (new seq) and replaces them in its index.
    """
    t = time.perf_counter()
    with ctx.db.read() as conn:
        record = vocab_repo.active(conn)
        ids = models_repo.ready_ids(conn)
    if record is None:
        raise InvalidInputError("no active vocabulary: rebuild the vocabulary first")
    ids, vectors = encode_version(ctx, record, ids)
    part_rows = encode_version_parts(ctx, record, ids)
    timings = {"encode": time.perf_counter() - t, "models": len(ids), "vocabulary_id": record.id,
               "object_rows": len(part_rows)}
    with ctx.db.write() as conn:
        store_vectors(conn, record.id, ids, vectors)
        object_rows.store_vectors(conn, record.id, part_rows)
        jobs_repo.mark_done(conn, job_id, timings)
    return timings


def encode_version(
    ctx: ServiceContext, record: VocabularyRecord, model_ids: list[int]
) -> tuple[list[int], np.ndarray]:
    """Encode `model_ids` from their cached descriptions with version `record` -> ids, (n, dim) vectors."""
    vocab = load_vocabulary(ctx, record)
    ids, descs = load_descriptions(ctx, model_ids)
    return ids, encode_all(vocab, descs, version_params(ctx, record, vocab))


def encode_version_parts(
    ctx: ServiceContext, record: VocabularyRecord, model_ids: list[int]
) -> list[tuple[int, int, np.ndarray]]:
    """The object rows of `model_ids` encoded with version `record`: (model id, part, vector) each."""
    parts = _parts_of(ctx, model_ids)
    if not parts:
        return []
    vocab = load_vocabulary(ctx, record)
    return object_rows.encode_parts(ctx, vocab, version_params(ctx, record, vocab), parts)


def _parts_of(ctx: ServiceContext, model_ids: list[int]) -> list[tuple[int, int]]:
    """(model id, part) of the ready object rows of `model_ids` (one scan of the few object rows, not an
    IN over every model id)."""
    wanted = set(model_ids)
    with ctx.db.read() as conn:
        return [(m, p) for m, p in objects_repo.ready_parts(conn) if m in wanted]


def store_vectors(conn: sqlite3.Connection, vocabulary_id: int, ids: list[int], vectors: np.ndarray) -> None:
    """Replace the stored vectors of the models of `ids` still alive (deleted meanwhile: skipped)."""
    alive = set(models_repo.get_many(conn, ids))
    for mid, vec in zip(ids, vectors, strict=True):
        if mid in alive:
            vocab_repo.put_vector(conn, mid, vocabulary_id, vec)


def reencode_version(ctx: ServiceContext, record: VocabularyRecord) -> int:
    """Re-encode every ready model with version `record` (its stored vectors were encoded under
    other settings: SHAPEBAG_ENCODE__FUSION flipped); returns how many."""
    with ctx.db.read() as conn:
        ready = models_repo.ready_ids(conn)
    ids, vectors = encode_version(ctx, record, ready)
    part_rows = encode_version_parts(ctx, record, ids)
    lost = sorted(set(ready) - set(ids))  # no cached description: cannot be encoded again
    with ctx.db.write() as conn:
        store_vectors(conn, record.id, ids, vectors)
        for mid in ids:  # object rows of another length would break the objects' index likewise
            objects_repo.delete_vectors(conn, mid, record.id)
        object_rows.store_vectors(conn, record.id, part_rows)
        for mid in lost:  # an old vector of another length beside the new ones would break the index
            vocab_repo.delete_vector(conn, mid, record.id)
            objects_repo.delete_vectors(conn, mid, record.id)
    if lost:
        log.warning("%d model(s) without a cached description leave version %d's index until ingested "
                    "again: %s", len(lost), record.id, ", ".join(map(str, lost[:10])))
    return len(ids)
