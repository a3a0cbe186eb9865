"""The ShapeIndex interface: an L1 nearest-neighbour index over BoF vectors, ids = model ids.

Backends (FAISS flat L1, numpy brute force; later e.g. Qdrant's Manhattan distance) all pass the
same test suite (tests/index/test_shape_index.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from app.storage.blobs import atomic_write


class IndexFileError(RuntimeError):
    """An index file is missing, unreadable or not what we expect."""


@runtime_checkable
class ShapeIndex(Protocol):
    dim: int

    @property
    def count(self) -> int: ...

    def ids(self) -> np.ndarray:
        """(n,) int64 ids held, sorted."""
        ...

    def add(self, ids: np.ndarray, vectors: np.ndarray) -> None:
        """ids (n,) int64, vectors (n, dim) float32; an id already present is replaced."""
        ...

    def remove(self, ids: np.ndarray) -> int:
        """Remove the ids present; returns how many were removed."""
        ...

    def search(
        self, vectors: np.ndarray, k: int, allowed_ids: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """vectors (q, dim) -> distances (q, k) float32 ascending, ids (q, k) int64.

        Only ids in `allowed_ids` are considered when given; missing neighbours are id -1, distance inf.
        """
        ...

    def save(self, path: Path) -> None: ...


def as_batch(ids: np.ndarray, vectors: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Validate an add(): (n,) int64 unique ids and (n, dim) float32 vectors."""
    ids, vectors = as_ids(ids), as_vectors(vectors, dim)
    if len(ids) != len(vectors):
        raise ValueError(f"{len(ids)} ids for {len(vectors)} vectors")
    if len(np.unique(ids)) != len(ids):
        raise ValueError("duplicate ids in one add")
    return ids, vectors


def no_hits(n_queries: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The answer when nothing can match: distances inf, ids -1, both (q, k)."""
    if k <= 0:
        raise ValueError("k must be positive")
    return np.full((n_queries, k), np.inf, np.float32), np.full((n_queries, k), -1, np.int64)


def faiss_hits(dist: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """FAISS search output -> (q, k) float32 distances with inf where no hit (id -1), (q, k) int64 ids."""
    return np.where(ids < 0, np.inf, dist).astype(np.float32), ids.astype(np.int64)


def write_faiss(index, path: Path) -> None:  # index: faiss.Index
    """Write a FAISS index file atomically (temp file, fsync, rename)."""
    import faiss

    atomic_write(Path(path), lambda tmp: faiss.write_index(index, str(tmp)))


def read_faiss(path: Path):  # -> faiss.Index (faiss is untyped; imported here only when a file is read)
    """Read a FAISS index file, turning a missing or corrupt file into IndexFileError."""
    import faiss

    path = Path(path)
    if not path.is_file():
        raise IndexFileError(f"no index file at {path}")
    try:
        return faiss.read_index(str(path))
    except RuntimeError as exc:
        raise IndexFileError(f"unreadable index file {path}: {str(exc).splitlines()[0]}") from exc


def as_ids(ids: np.ndarray | list[int]) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(ids, dtype=np.int64).reshape(-1))


def as_vectors(vectors: np.ndarray, dim: int) -> np.ndarray:
    v = np.ascontiguousarray(np.asarray(vectors, dtype=np.float32))
    if v.ndim == 1:
        v = v.reshape(1, -1)
    if v.ndim != 2 or v.shape[1] != dim:
        raise ValueError(f"vectors must be (n, {dim}), got {v.shape}")
    return v
