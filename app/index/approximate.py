"""ApproxL1Index: exact L1 while small, FAISS IVF-Flat with the L1 metric once large; ids = model ids.

Below `train_at` vectors it is an IndexIDMap2 over IndexFlat(L1) (exact, like FaissL1Index). When an
add crosses `train_at` it trains an inverted file (in a background thread, see below): nlist ≈ 4·√n
coarse cells (k-means, FAISS's IVF training), an L1 coarse quantizer, full float32 vectors in the
lists (IVF-Flat, no compression, so distances returned are exact L1 distances: only the candidate set
is approximate). A query scans the `nprobe` nearest cells. When the index has grown RETRAIN_FACTOR x
past its training size, the next add retrains (nlist grows with √n). benchmarks/search.py measures
recall@10 against the flat index on real BoF vectors (docs/performance.md).

Training runs to the side: the add that triggers it snapshots the vectors and starts a thread that
builds the IVF, while this object keeps answering from the index it had (flat, or the previous IVF)
and logs every add/remove made meanwhile. The next call after the build finishes replays the log on
the new IVF and swaps it in, so a caller that serialises its calls (the service's LiveIndex holds a
lock around them) never waits for k-means. `wait_for_training()` blocks until the swap (tests, tools).

Memory: the IVF holds the vectors once (n·dim·4 bytes) plus an id hashtable for reconstruction;
while a build runs, the snapshot and the old index are held too (about 3x for that time).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import faiss as _faiss_typed
import numpy as np

from app.index.base import (
    IndexFileError,
    as_batch,
    as_ids,
    as_vectors,
    faiss_hits,
    no_hits,
    read_faiss,
    write_faiss,
)

# faiss's type stubs lack DirectMap, IVF attributes and the SearchParameters keywords: use it untyped
faiss: Any = _faiss_typed

TRAIN_AT = 20_000  # below this many vectors the flat scan is already < ~1 ms per query
MAX_NLIST = 2048
RETRAIN_FACTOR = 8.0
TRAIN_SAMPLE_PER_LIST = 32  # k-means sample size per coarse cell
TRAIN_ITERATIONS = 10  # k-means iterations: coarse cells need not be optimal, only cheap to build


def nlist_for(n: int) -> int:
    """Coarse cells for n vectors: ~4·√n, at least 16, at most MAX_NLIST."""
    return int(np.clip(4 * np.sqrt(max(n, 1)), 16, MAX_NLIST))


def default_nprobe(nlist: int) -> int:
    """Cells scanned per query: 1/16 of them, at least 8 (see docs/performance.md for recall@10)."""
    return int(min(nlist, max(8, nlist // 16)))


class ApproxL1Index:
    def __init__(
        self,
        dim: int,
        index: Any = None,
        train_at: int = TRAIN_AT,
        nprobe: int | None = None,
        trained_count: int = 0,
        background: bool = True,
    ) -> None:
        self.dim = dim
        self.train_at = train_at
        self.nprobe = nprobe
        self.trained_count = trained_count
        self.background = background
        self._index = index if index is not None else _flat(dim)
        self._ids = _held_ids(self._index)  # (n,) sorted int64 mirror of the ids held
        self._builder: threading.Thread | None = None
        self._built: list = []  # [(ivf, trained_count)] once the builder is done; [exc] if it failed
        self._log: list[tuple[str, np.ndarray, np.ndarray | None]] = []  # ops since the snapshot

    @property
    def approximate(self) -> bool:
        return isinstance(self._index, faiss.IndexIVF)

    @property
    def count(self) -> int:
        return int(self._index.ntotal)

    def ids(self) -> np.ndarray:
        return self._ids.copy()

    def add(self, ids: np.ndarray, vectors: np.ndarray) -> None:
        ids, vectors = as_batch(ids, vectors, self.dim)
        self._maybe_swap()
        self.remove(ids)  # a re-added id replaces its vector
        self._index.add_with_ids(vectors, ids)
        self._ids = np.union1d(self._ids, ids)
        if self._builder is not None:
            self._log.append(("add", ids, vectors.copy()))
        elif self._needs_training():
            self._start_training()

    def remove(self, ids: np.ndarray) -> int:
        ids = as_ids(ids)
        self._maybe_swap()
        present = ids[np.isin(ids, self._ids)]
        if len(present) == 0:
            return 0
        removed = _remove(self._index, present)
        self._ids = np.setdiff1d(self._ids, present, assume_unique=True)
        if self._builder is not None:
            self._log.append(("remove", present, None))
        return removed

    @property
    def training(self) -> bool:
        """True while a background build runs (searches use the previous index meanwhile)."""
        return self._builder is not None

    def wait_for_training(self, timeout: float | None = None) -> None:
        """Block until a running build is swapped in (re-raises its error, if it failed)."""
        if self._builder is not None:
            self._builder.join(timeout)
        self._maybe_swap()

    def search(
        self, vectors: np.ndarray, k: int, allowed_ids: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        q = as_vectors(vectors, self.dim)
        empty = no_hits(len(q), k)  # also checks k
        self._maybe_swap()
        if self.count == 0 or (allowed_ids is not None and len(allowed_ids) == 0):
            return empty
        sel = faiss.IDSelectorBatch(as_ids(allowed_ids)) if allowed_ids is not None else None
        if self.approximate:
            nprobe = self.nprobe or default_nprobe(self._index.nlist)
            params = (
                faiss.SearchParametersIVF(sel=sel, nprobe=nprobe)
                if sel
                else faiss.SearchParametersIVF(nprobe=nprobe)
            )
        else:
            params = faiss.SearchParameters(sel=sel) if sel else None
        return faiss_hits(*self._index.search(q, k, params=params))

    def save(self, path: Path) -> None:
        write_faiss(self._index, path)

    @classmethod
    def load(cls, path: Path) -> ApproxL1Index:
        index = read_faiss(path)
        if isinstance(index, faiss.IndexIVFFlat):
            if index.direct_map.type != faiss.DirectMap.Hashtable:
                index.set_direct_map_type(faiss.DirectMap.Hashtable)
            trained = int(index.ntotal)
        elif isinstance(index, faiss.IndexIDMap2):
            trained = 0
        else:
            raise IndexFileError(f"{path} is neither an IVF-Flat nor an IndexIDMap2 index")
        if index.metric_type != faiss.METRIC_L1:
            raise IndexFileError(f"{path} does not use the L1 metric")
        return cls(index.d, index, trained_count=trained)

    def _needs_training(self) -> bool:
        if not self.approximate:
            return self.count >= self.train_at
        return self.count >= RETRAIN_FACTOR * max(self.trained_count, 1) and (
            nlist_for(self.count) > self._index.nlist
        )

    def _start_training(self) -> None:
        """Snapshot every vector held and build an IVF from it, in a thread unless background=False."""
        ids = self._ids.copy()
        vectors = self._index.reconstruct_batch(ids) if self.approximate else _flat_vectors(self._index, ids)
        self._log, self._built = [], []
        if not self.background:
            self._index, self.trained_count = _build_ivf(self.dim, ids, vectors), len(ids)
            return

        def build() -> None:
            try:
                self._built.append((_build_ivf(self.dim, ids, vectors), len(ids)))
            except Exception as exc:  # surfaced by the next call, in the caller's thread
                self._built.append(exc)

        self._builder = threading.Thread(target=build, name="ivf-build", daemon=True)
        self._builder.start()

    def _maybe_swap(self) -> None:
        """If the background build is done: replay the adds/removes made meanwhile, then swap it in."""
        if self._builder is None or self._builder.is_alive():
            return
        self._builder = None
        log, self._log = self._log, []
        result = (
            self._built.pop() if self._built else RuntimeError("the IVF build thread ended without a result")
        )
        if isinstance(result, BaseException):
            raise result
        ivf, trained = result
        for op, ids, vectors in log:
            _remove(ivf, ids)
            if op == "add":
                ivf.add_with_ids(vectors, ids)
        self._index, self.trained_count = ivf, trained


def _build_ivf(dim: int, ids: np.ndarray, vectors: np.ndarray) -> Any:
    """IVF-Flat (L1) over `vectors` (n, dim) with `ids` (n,): seconds at 1e6 vectors."""
    nlist = nlist_for(len(ids))
    quantizer = faiss.IndexFlat(dim, faiss.METRIC_L1)
    ivf = faiss.IndexIVFFlat(quantizer, dim, nlist, faiss.METRIC_L1)
    ivf.own_fields = True
    quantizer.this.disown()  # the IVF owns and frees its quantizer
    ivf.cp.seed = 1234
    ivf.cp.max_points_per_centroid = TRAIN_SAMPLE_PER_LIST
    ivf.cp.min_points_per_centroid = 1  # no warning for small samples
    ivf.cp.niter = TRAIN_ITERATIONS
    ivf.train(vectors)
    ivf.set_direct_map_type(faiss.DirectMap.Hashtable)
    ivf.add_with_ids(vectors, ids)
    return ivf


def _remove(index: Any, ids: np.ndarray) -> int:
    if len(ids) == 0:
        return 0
    # an IVF with a hashtable direct map removes only through an IDSelectorArray
    selector = faiss.IDSelectorArray(ids) if isinstance(index, faiss.IndexIVF) else faiss.IDSelectorBatch(ids)
    return int(index.remove_ids(selector))


def _flat(dim: int) -> Any:
    return faiss.IndexIDMap2(faiss.IndexFlat(dim, faiss.METRIC_L1))


def _flat_vectors(index: Any, ids: np.ndarray) -> np.ndarray:
    """(n, dim) vectors of an IndexIDMap2 ordered like `ids`."""
    stored = faiss.vector_to_array(index.id_map).astype(np.int64)
    raw = index.index.reconstruct_n(0, index.ntotal)
    order = np.argsort(stored)
    return np.ascontiguousarray(raw[order[np.searchsorted(stored[order], ids)]])


def _held_ids(index: Any) -> np.ndarray:
    if isinstance(index, faiss.IndexIDMap2):
        return np.sort(faiss.vector_to_array(index.id_map).astype(np.int64))
    invlists = index.invlists
    parts = [
        faiss.rev_swig_ptr(invlists.get_ids(i), invlists.list_size(i)).copy()
        for i in range(index.nlist)
        if invlists.list_size(i) > 0
    ]
    return np.sort(np.concatenate(parts).astype(np.int64)) if parts else np.zeros(0, np.int64)
