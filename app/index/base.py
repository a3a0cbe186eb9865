"""The ShapeIndex interface: an L1 nearest-neighbour index over BoF vectors, ids = model ids.

Backends (FAISS flat L1, numpy brute force; later e.g. Qdrant's Manhattan distance) all pass the
same test suite (tests/index/test_shape_index.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np


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


def as_ids(ids: np.ndarray | list[int]) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(ids, dtype=np.int64).reshape(-1))


def as_vectors(vectors: np.ndarray, dim: int) -> np.ndarray:
    v = np.ascontiguousarray(np.asarray(vectors, dtype=np.float32))
    if v.ndim == 1:
        v = v.reshape(1, -1)
    if v.ndim != 2 or v.shape[1] != dim:
        raise ValueError(f"vectors must be (n, {dim}), got {v.shape}")
    return v
