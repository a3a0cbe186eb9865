"""The API process's view of the active (vocabulary, index) pair, kept in step with the database.

Workers write BoF rows; this object follows them through a cursor on the rows' seq (cheap polling),
swaps to a new vocabulary version when the database says another is active, and on load reconciles
the saved index file with the stored vectors (a missing, unreadable or disagreeing file is rebuilt).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass

import numpy as np

from app.core.pipeline import ShapeDescription
from app.core.vocabulary import EncodeParams, Vocabulary
from app.index import IndexFileError, ShapeIndex, load_index, new_index
from app.services.context import ServiceContext
from app.services.errors import NotReadyError
from app.services.vocabularies import encode_missing, load_vocabulary, reencode_version, version_params
from app.storage import models as models_repo
from app.storage import objects as objects_repo
from app.storage import vocabularies as vocab_repo
from app.storage.vocabularies import VocabularyRecord

log = logging.getLogger(__name__)


@dataclass
class ActivePair:
    record: VocabularyRecord
    vocabulary: Vocabulary
    index: ShapeIndex
    cursor: int  # highest bof.seq of this version already in `index`
    params: EncodeParams  # how this version encodes its vectors and the queries (version_params)
    dirty: bool = False
    reconciled: str = ""  # what happened at load: "loaded" | "created" (no vectors yet) | "rebuilt: <why>"
    objects: ObjectRows | None = None  # the object rows of multi-object files (services/object_rows)


class ObjectRows:
    """The object rows of one version: an exact L1 index over row ids (storage.objects.row_id), and
    the rows' vectors (the fusion re-rank reads a hit's). Built from the database at load, never saved:
    only multi-object files have rows, a few per file."""

    def __init__(self, backend: str, dim: int) -> None:
        self.index = new_index("numpy" if backend == "numpy" else "faiss", dim)
        self.vectors: dict[int, np.ndarray] = {}
        self.cursor = 0  # highest object_bof.seq of this version already held

    def add(self, row_ids: np.ndarray, vectors: np.ndarray) -> None:
        self.index.add(row_ids, vectors)
        self.vectors.update((int(r), v) for r, v in zip(row_ids, vectors, strict=True))

    def remove_models(self, model_ids: set[int]) -> None:
        gone = [r for r in self.vectors if r >> objects_repo.PART_BITS in model_ids]
        if gone:
            self.index.remove(np.asarray(gone, np.int64))
            for r in gone:
                del self.vectors[r]

    def search(self, vector: np.ndarray, k: int, allowed_models: np.ndarray | None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """vector (v,) -> distances (<= k,), model ids (<= k,), parts (<= k,) of the nearest rows."""
        if not self.vectors:
            return np.zeros(0, np.float32), np.zeros(0, np.int64), np.zeros(0, np.int64)
        allowed = None
        if allowed_models is not None:
            rows = np.fromiter(self.vectors, np.int64)
            allowed = rows[np.isin(objects_repo.split_row_ids(rows)[0], allowed_models)]
            if len(allowed) == 0:
                return np.zeros(0, np.float32), np.zeros(0, np.int64), np.zeros(0, np.int64)
        dist, ids = self.index.search(vector.reshape(1, -1), min(k, len(self.vectors)), allowed)
        keep = ids[0] >= 0
        models, parts = objects_repo.split_row_ids(ids[0][keep])
        return dist[0][keep], models, parts


class LiveIndex:
    def __init__(self, ctx: ServiceContext) -> None:
        self.ctx = ctx
        self._lock = threading.RLock()
        self._refresh_lock = threading.Lock()
        self.pair: ActivePair | None = None
        self._deleted: set[int] = (
            set()
        )  # ids never come back (AUTOINCREMENT); a late poll must not re-add them
        self.last_saved = time.monotonic()
        self._deletions_seen = 0  # deletions.seq: deletes served by other replicas reach this one too

    # --- loading and following the database ---------------------------------------------------------

    def _load_pair(self, record: VocabularyRecord) -> ActivePair:
        vocab = load_vocabulary(self.ctx, record)
        params = version_params(self.ctx, record, vocab)
        dim = vocab.dimension(params)  # v words, + c with Shape-DNA fusion
        encode_missing(self.ctx, record.id)  # e.g. ready before any vocabulary existed
        with self.ctx.db.read() as conn:
            ids, vectors, cursor = vocab_repo.vectors(conn, record.id)
        if len(ids) and vectors.shape[1] != dim:  # stored under other encode settings (fusion flipped)
            log.warning("vectors of vocabulary %d are %d-long, %d expected: re-encoding", record.id,
                        vectors.shape[1], dim)
            reencode_version(self.ctx, record)
            with self.ctx.db.read() as conn:
                ids, vectors, cursor = vocab_repo.vectors(conn, record.id)
        backend = self.ctx.settings.index_backend
        path = self.ctx.index_path(record.id)
        why = ""
        try:
            index = load_index(backend, path)
            if index.dim != dim:
                why = f"dimension {index.dim} != {dim} ({vocab.size} words, fused: {dim > vocab.size})"
            elif not np.array_equal(index.ids(), np.sort(ids)):
                why = f"{index.count} ids in the file, {len(ids)} in the database"
        except IndexFileError as exc:
            why = str(exc)
        reconciled = "loaded"
        if why:
            index = new_index(backend, dim)
            if len(ids):
                index.add(ids, vectors)
                log.warning("index of vocabulary %d rebuilt from stored vectors: %s", record.id, why)
                reconciled = f"rebuilt: {why}"
            else:  # a fresh data directory (or a version with no model yet): nothing was lost
                log.info("index of vocabulary %d created empty (%s)", record.id, why)
                reconciled = "created"
            index.save(path)
        pair = ActivePair(record, vocab, index, cursor, params, reconciled=reconciled,
                          objects=ObjectRows(backend, dim))
        self._follow_objects(pair)
        return pair

    def _follow_objects(self, pair: ActivePair) -> int:
        """Add the object rows stored for `pair`'s version since its cursor; returns how many."""
        rows = pair.objects
        if rows is None:
            return 0
        with self.ctx.db.read() as conn:
            ids, vectors, cursor = objects_repo.vectors(conn, pair.record.id, rows.cursor)
        if len(ids) == 0:
            return 0
        models = objects_repo.split_row_ids(ids)[0]
        keep = ~np.isin(models, list(self._deleted)) & (vectors.shape[1] == rows.index.dim)
        with self._lock:
            rows.cursor = cursor
            if keep.any():
                rows.add(ids[keep], vectors[keep])
        return int(keep.sum())

    def refresh(self) -> int:
        """Follow the database: swap to a newly active version, add newly encoded models.

        Returns the number of vectors added/replaced. Called periodically by the lifespan's poller.
        """
        with self._refresh_lock:
            with self.ctx.db.read() as conn:
                record = vocab_repo.active(conn)
                gone, self._deletions_seen = models_repo.deleted_since(conn, self._deletions_seen)
            if gone:  # before the vectors: a model deleted after this read has no vectors left to add
                self.remove(gone)
            if record is None:
                return 0
            current = self.pair
            if current is None or current.record.id != record.id:
                pair = self._load_pair(record)  # outside the search lock: queries use the old pair
                with self._lock:
                    old, self.pair = self.pair, pair
                if old is not None and old.dirty:
                    old.index.save(self.ctx.index_path(old.record.id))
                log.info(
                    "now serving vocabulary version %d (%d models, %s)",
                    record.id,
                    pair.index.count,
                    pair.reconciled,
                )
                return pair.index.count
            with self.ctx.db.read() as conn:
                ids, vectors, cursor = vocab_repo.vectors(conn, record.id, current.cursor)
            self._follow_objects(current)
            if len(ids) == 0:
                return 0
            last = {int(i): k for k, i in enumerate(ids)}  # a model re-encoded twice: keep its last row
            with self._lock:
                keep = np.array(sorted(k for i, k in last.items() if i not in self._deleted), dtype=np.int64)
                current.cursor = cursor
                if len(keep) == 0:
                    return 0
                current.index.add(ids[keep], vectors[keep])
                current.dirty = True
            return len(keep)

    def remove(self, model_ids: list[int]) -> None:
        with self._lock:
            self._deleted.update(int(i) for i in model_ids)
            if self.pair is not None and self.pair.index.remove(np.asarray(model_ids, np.int64)):
                self.pair.dirty = True
            if self.pair is not None and self.pair.objects is not None:
                self.pair.objects.remove_models({int(i) for i in model_ids})

    def save(self, force: bool = False) -> bool:
        """Persist the index if it changed (periodically and at shutdown)."""
        with self._lock:
            pair = self.pair
            if pair is None or not (pair.dirty or force):
                return False
            pair.index.save(self.ctx.index_path(pair.record.id))
            pair.dirty = False
        self.last_saved = time.monotonic()
        return True

    # --- answering ------------------------------------------------------------------------------------

    def require(self) -> ActivePair:
        pair = self.pair
        if pair is None:
            raise NotReadyError(
                "no vocabulary is active yet: an admin must run POST /admin/vocabulary/rebuild"
                " once models are ready"
            )
        return pair

    def encode(self, description: ShapeDescription) -> tuple[int, np.ndarray]:
        """(vocabulary id, (v,) float32 BoF) of a query, with the pair that will answer it."""
        pair = self.require()
        return pair.record.id, pair.vocabulary.encode(description, pair.params)

    def search(
        self,
        vector: np.ndarray,
        k: int,
        allowed_ids: np.ndarray | None = None,
        vocabulary_id: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """vector (v,) -> distances (k,), ids (k,) and the version that answered (-1 ids dropped)."""
        with self._lock:
            pair = self.require()
            if vocabulary_id is not None and vocabulary_id != pair.record.id:
                raise NotReadyError("the vocabulary changed while the query was encoded; retry")
            dist, ids = pair.index.search(vector.reshape(1, -1), k, allowed_ids)
        keep = ids[0] >= 0
        return dist[0][keep], ids[0][keep], pair.record.id

    def search_objects(
        self, vector: np.ndarray, k: int, allowed_ids: np.ndarray | None = None,
        vocabulary_id: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """vector (v,) -> distances (<= k,), model ids (<= k,), parts (<= k,) of the nearest object rows
        (ObjectRows.search) of the version `vocabulary_id`'s pair."""
        with self._lock:
            pair = self.require()
            if vocabulary_id is not None and vocabulary_id != pair.record.id:
                raise NotReadyError("the vocabulary changed while the query was encoded; retry")
            if pair.objects is None:
                return np.zeros(0, np.float32), np.zeros(0, np.int64), np.zeros(0, np.int64)
            return pair.objects.search(vector, k, allowed_ids)

    def object_vector(self, model_id: int, part: int) -> np.ndarray | None:
        """One object row's vector under the active version (None: not held)."""
        pair = self.pair
        if pair is None or pair.objects is None:
            return None
        return pair.objects.vectors.get(objects_repo.row_id(model_id, part))

    def status(self) -> dict:
        pair = self.pair
        if pair is None:
            return {"vocabulary_id": None, "indexed": 0, "words": None}
        objects = 0 if pair.objects is None else len(pair.objects.vectors)
        return {"vocabulary_id": pair.record.id, "indexed": pair.index.count, "words": pair.vocabulary.size,
                "object_rows": objects}
