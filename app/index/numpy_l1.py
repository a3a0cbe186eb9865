"""NumpyL1Index: brute-force L1 search in numpy; the reference every backend is tested against."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from app.index.base import IndexFileError, as_batch, as_ids, as_vectors, no_hits
from app.storage.blobs import atomic_write


class NumpyL1Index:
    def __init__(self, dim: int) -> None:
        self.dim = dim
        self._ids = np.zeros(0, np.int64)  # (n,)
        self._vectors = np.zeros((0, dim), np.float32)  # (n, dim)

    @property
    def count(self) -> int:
        return int(len(self._ids))

    def ids(self) -> np.ndarray:
        return np.sort(self._ids)

    def add(self, ids: np.ndarray, vectors: np.ndarray) -> None:
        ids, vectors = as_batch(ids, vectors, self.dim)
        self.remove(ids)
        self._ids = np.concatenate([self._ids, ids])
        self._vectors = np.concatenate([self._vectors, vectors])

    def remove(self, ids: np.ndarray) -> int:
        keep = ~np.isin(self._ids, as_ids(ids))
        removed = int((~keep).sum())
        self._ids, self._vectors = self._ids[keep], self._vectors[keep]
        return removed

    def search(
        self, vectors: np.ndarray, k: int, allowed_ids: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        q = as_vectors(vectors, self.dim)
        out_d, out_i = no_hits(len(q), k)  # also checks k
        mask = np.ones(self.count, bool) if allowed_ids is None else np.isin(self._ids, as_ids(allowed_ids))
        ids, base = self._ids[mask], self._vectors[mask]
        if len(ids) == 0:
            return out_d, out_i
        dist = np.abs(q[:, None, :] - base[None, :, :]).sum(axis=2)  # (q, n)
        order = np.argsort(dist, axis=1, kind="stable")[:, :k]
        n = order.shape[1]
        out_d[:, :n] = np.take_along_axis(dist, order, axis=1)
        out_i[:, :n] = ids[order]
        return out_d, out_i

    def save(self, path: Path) -> None:
        buf = io.BytesIO()
        np.savez(buf, ids=self._ids, vectors=self._vectors)
        atomic_write(Path(path), buf.getvalue())

    @classmethod
    def load(cls, path: Path) -> NumpyL1Index:
        path = Path(path)
        if not path.is_file():
            raise IndexFileError(f"no index file at {path}")
        try:
            with np.load(path, allow_pickle=False) as z:
                ids, vectors = z["ids"].astype(np.int64), z["vectors"].astype(np.float32)
        except (OSError, ValueError, KeyError) as exc:
            raise IndexFileError(f"unreadable index file {path}: {exc}") from exc
        index = cls(vectors.shape[1])
        index._ids, index._vectors = ids, vectors
        return index
