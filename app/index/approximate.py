"""ApproxL1Index: exact L1 while small, FAISS IVF-Flat with the L1 metric once large; ids = model ids.

Below `train_at` vectors it is an IndexIDMap2 over IndexFlat(L1) (exact, like FaissL1Index). When an
add crosses `train_at` it trains an inverted file: nlist ≈ 4·√n coarse cells (k-means, FAISS's IVF
training), an L1 coarse quantizer, full float32 vectors in the lists (IVF-Flat, no compression, so
distances returned are exact L1 distances: only the candidate set is approximate). A query scans the
`nprobe` nearest cells. When the index has grown `retrain_factor`x past its training size, the next
add retrains (nlist grows with √n). benchmarks/search.py measures recall@10 against the flat index on
real BoF vectors (docs/performance.md); the defaults keep recall@10 ≥ 0.95 there.

Memory: the IVF holds the vectors once (n·dim·4 bytes) plus an id hashtable for reconstruction.
"""

from __future__ import annotations

from pathlib import Path

import faiss
import numpy as np

from app.index.base import IndexFileError, as_ids, as_vectors
from app.storage.blobs import atomic_write

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
        self, dim: int, index: faiss.Index | None = None, train_at: int = TRAIN_AT, nprobe: int | None = None,
        trained_count: int = 0,
    ) -> None:
        self.dim = dim
        self.train_at = train_at
        self.nprobe = nprobe
        self.trained_count = trained_count
        self._index = index if index is not None else _flat(dim)
        self._ids = _held_ids(self._index)  # (n,) sorted int64 mirror of the ids held

    @property
    def approximate(self) -> bool:
        return isinstance(self._index, faiss.IndexIVF)

    @property
    def count(self) -> int:
        return int(self._index.ntotal)

    def ids(self) -> np.ndarray:
        return self._ids.copy()

    def add(self, ids: np.ndarray, vectors: np.ndarray) -> None:
        ids, vectors = as_ids(ids), as_vectors(vectors, self.dim)
        if len(ids) != len(vectors):
            raise ValueError(f"{len(ids)} ids for {len(vectors)} vectors")
        if len(np.unique(ids)) != len(ids):
            raise ValueError("duplicate ids in one add")
        self.remove(ids)  # a re-added id replaces its vector
        self._index.add_with_ids(vectors, ids)
        self._ids = np.union1d(self._ids, ids)
        if self._needs_training():
            self._train()

    def remove(self, ids: np.ndarray) -> int:
        ids = as_ids(ids)
        present = ids[np.isin(ids, self._ids)]
        if len(present) == 0:
            return 0
        # an IVF with a hashtable direct map removes only through an IDSelectorArray
        selector = faiss.IDSelectorArray(present) if self.approximate else faiss.IDSelectorBatch(present)
        removed = int(self._index.remove_ids(selector))
        self._ids = np.setdiff1d(self._ids, present, assume_unique=True)
        return removed

    def search(
        self, vectors: np.ndarray, k: int, allowed_ids: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        q = as_vectors(vectors, self.dim)
        if k <= 0:
            raise ValueError("k must be positive")
        if self.count == 0 or (allowed_ids is not None and len(allowed_ids) == 0):
            return np.full((len(q), k), np.inf, np.float32), np.full((len(q), k), -1, np.int64)
        sel = faiss.IDSelectorBatch(as_ids(allowed_ids)) if allowed_ids is not None else None
        if self.approximate:
            nprobe = self.nprobe or default_nprobe(self._index.nlist)
            params = faiss.SearchParametersIVF(sel=sel, nprobe=nprobe) if sel else faiss.SearchParametersIVF(
                nprobe=nprobe
            )
        else:
            params = faiss.SearchParameters(sel=sel) if sel else None
        dist, got = self._index.search(q, k, params=params)
        dist = np.where(got < 0, np.inf, dist).astype(np.float32)
        return dist, got.astype(np.int64)

    def save(self, path: Path) -> None:
        atomic_write(Path(path), lambda tmp: faiss.write_index(self._index, str(tmp)))

    @classmethod
    def load(cls, path: Path) -> ApproxL1Index:
        path = Path(path)
        if not path.is_file():
            raise IndexFileError(f"no index file at {path}")
        try:
            index = faiss.read_index(str(path))
        except RuntimeError as exc:
            raise IndexFileError(f"unreadable index file {path}: {str(exc).splitlines()[0]}") from exc
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

    def _train(self) -> None:
        """(Re)build the IVF from every vector held (seconds at 1e6 vectors, once per growth step)."""
        ids = self._ids
        vectors = self._index.reconstruct_batch(ids) if self.approximate else _flat_vectors(self._index, ids)
        nlist = nlist_for(len(ids))
        quantizer = faiss.IndexFlat(self.dim, faiss.METRIC_L1)
        ivf = faiss.IndexIVFFlat(quantizer, self.dim, nlist, faiss.METRIC_L1)
        ivf.own_fields = True
        quantizer.this.disown()  # the IVF owns and frees its quantizer
        ivf.cp.seed = 1234
        ivf.cp.max_points_per_centroid = TRAIN_SAMPLE_PER_LIST
        ivf.cp.min_points_per_centroid = 1  # no warning for small samples
        ivf.cp.niter = TRAIN_ITERATIONS
        ivf.train(vectors)
        ivf.set_direct_map_type(faiss.DirectMap.Hashtable)
        ivf.add_with_ids(vectors, ids)
        self._index = ivf
        self.trained_count = len(ids)


def _flat(dim: int) -> faiss.Index:
    return faiss.IndexIDMap2(faiss.IndexFlat(dim, faiss.METRIC_L1))


def _flat_vectors(index: faiss.IndexIDMap2, ids: np.ndarray) -> np.ndarray:
    """(n, dim) vectors of an IndexIDMap2 ordered like `ids`."""
    stored = faiss.vector_to_array(index.id_map).astype(np.int64)
    raw = index.index.reconstruct_n(0, index.ntotal)
    order = np.argsort(stored)
    return np.ascontiguousarray(raw[order[np.searchsorted(stored[order], ids)]])


def _held_ids(index: faiss.Index) -> np.ndarray:
    if isinstance(index, faiss.IndexIDMap2):
        return np.sort(faiss.vector_to_array(index.id_map).astype(np.int64))
    invlists = index.invlists
    parts = [
        faiss.rev_swig_ptr(invlists.get_ids(i), invlists.list_size(i)).copy()
        for i in range(index.nlist)
        if invlists.list_size(i) > 0
    ]
    return np.sort(np.concatenate(parts).astype(np.int64)) if parts else np.zeros(0, np.int64)
