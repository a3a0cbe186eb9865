"""FaissL1Index: IndexIDMap2 over IndexFlat(dim, METRIC_L1); exact L1 search, ids = model ids."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import faiss
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

# below this many (query, vector) pairs one thread wins: waking an OpenMP team costs more than the scan
# (measured on 2 busy cores: a 1-query search over 40 vectors took ~20 ms with 2 threads, ~0.05 ms with 1)
SINGLE_THREAD_WORK = 200_000


@contextmanager
def _single_thread_if(small: bool) -> Iterator[None]:
    if not small:
        yield
        return
    previous = faiss.omp_get_max_threads()  # per calling thread: other threads are unaffected
    faiss.omp_set_num_threads(1)
    try:
        yield
    finally:
        faiss.omp_set_num_threads(previous)


class FaissL1Index:
    def __init__(self, dim: int, index: faiss.Index | None = None) -> None:
        self.dim = dim
        self._index = index if index is not None else faiss.IndexIDMap2(faiss.IndexFlat(dim, faiss.METRIC_L1))

    @property
    def count(self) -> int:
        return int(self._index.ntotal)

    def ids(self) -> np.ndarray:
        return np.sort(faiss.vector_to_array(self._index.id_map).astype(np.int64))  # type: ignore[attr-defined]

    def add(self, ids: np.ndarray, vectors: np.ndarray) -> None:
        ids, vectors = as_batch(ids, vectors, self.dim)
        self.remove(ids)  # IndexIDMap2 would keep both copies of a re-added id
        self._index.add_with_ids(vectors, ids)

    def remove(self, ids: np.ndarray) -> int:
        ids = as_ids(ids)
        if len(ids) == 0 or self.count == 0:
            return 0
        return int(self._index.remove_ids(faiss.IDSelectorBatch(ids)))

    def search(
        self, vectors: np.ndarray, k: int, allowed_ids: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        q = as_vectors(vectors, self.dim)
        empty = no_hits(len(q), k)  # also checks k
        if self.count == 0 or (allowed_ids is not None and len(allowed_ids) == 0):
            return empty
        params = None
        if allowed_ids is not None:
            params = faiss.SearchParameters(sel=faiss.IDSelectorBatch(as_ids(allowed_ids)))  # type: ignore[call-arg]
        with _single_thread_if(len(q) * self.count <= SINGLE_THREAD_WORK):
            dist, ids = self._index.search(q, k, params=params)
        return faiss_hits(dist, ids)

    def save(self, path: Path) -> None:
        write_faiss(self._index, path)

    @classmethod
    def load(cls, path: Path) -> FaissL1Index:
        index = read_faiss(path)
        if not isinstance(index, faiss.IndexIDMap2) or index.metric_type != faiss.METRIC_L1:
            raise IndexFileError(f"{path} is not an IndexIDMap2 with the L1 metric")
        return cls(index.d, index)
