"""Nearest-neighbour lookup of fingerprints: the candidate step, sublinear in the collection.

Entries are (key, fingerprint) pairs; one model contributes its whole surface and each of its objects,
so a part finds the plate that holds it and a plate finds its parts. FAISS HNSW over L2: a graph search
whose cost grows with log(n); below `exact_below` entries a flat scan is both exact and as fast.
"""

from __future__ import annotations

import faiss
import numpy as np

from app.core.variants.fingerprint import DIM


class FingerprintIndex:
    def __init__(self, exact_below: int = 20_000, neighbours: int = 32, ef_search: int = 64) -> None:
        self._exact_below, self._m, self._ef = exact_below, neighbours, ef_search
        self._vectors = np.zeros((0, DIM), np.float32)
        self._keys = np.zeros(0, np.int64)
        self._ordered = True  # keys non-decreasing (models stored in id order): rows() by bisection
        self._index: faiss.Index | None = None

    def __len__(self) -> int:
        return len(self._keys)

    def build(self, keys: np.ndarray, vectors: np.ndarray) -> None:
        """keys (n,) int64 (several rows may share a key), vectors (n, DIM) float32."""
        self._keys = np.asarray(keys, np.int64)
        self._ordered = bool(np.all(np.diff(self._keys) >= 0))
        self._vectors = np.ascontiguousarray(vectors, dtype=np.float32).reshape(-1, DIM)
        if len(self._keys) < self._exact_below:
            self._index = faiss.IndexFlatL2(DIM)
        else:
            hnsw = faiss.IndexHNSWFlat(DIM, self._m)
            hnsw.hnsw.efConstruction = 80
            hnsw.hnsw.efSearch = self._ef
            self._index = hnsw
        self._index.add(self._vectors)

    def add(self, keys: np.ndarray, vectors: np.ndarray) -> None:
        """Append rows (a graph index grows in place; a flat one becomes a graph past `exact_below`)."""
        keys = np.asarray(keys, np.int64)
        vectors = np.ascontiguousarray(vectors, dtype=np.float32).reshape(-1, DIM)
        flat = isinstance(self._index, faiss.IndexFlatL2)
        if self._index is None or (flat and len(self._keys) + len(keys) >= self._exact_below):
            self.build(np.concatenate([self._keys, keys]), np.concatenate([self._vectors, vectors]))
            return
        self._ordered = self._ordered and bool(np.all(np.diff(keys) >= 0)) and (
            not len(self._keys) or not len(keys) or keys[0] >= self._keys[-1])
        self._keys = np.concatenate([self._keys, keys])
        self._vectors = np.concatenate([self._vectors, vectors])
        self._index.add(vectors)

    def rows(self, key: int) -> np.ndarray:
        """(r, DIM) float32: the fingerprints stored under `key` (a model's whole and its objects); by
        bisection while the keys came in order, else by a scan."""
        if self._ordered:
            lo, hi = np.searchsorted(self._keys, key, "left"), np.searchsorted(self._keys, key, "right")
            return self._vectors[lo:hi]
        return self._vectors[self._keys == key]

    def search(self, queries: np.ndarray, k: int = 16) -> tuple[np.ndarray, np.ndarray]:
        """queries (q, DIM) -> (keys (q, k) int64, L2 distances (q, k)); key -1 where fewer exist."""
        queries = np.ascontiguousarray(queries, dtype=np.float32).reshape(-1, DIM)
        if self._index is None or not len(self._keys):
            return np.full((len(queries), k), -1, np.int64), np.full((len(queries), k), np.inf)
        dist, rows = self._index.search(queries, k)
        keys = np.where(rows >= 0, self._keys[np.maximum(rows, 0)], -1)
        return keys, np.sqrt(np.maximum(dist, 0.0))

    def nearest(self, queries: np.ndarray, k: int = 16, radius: float = 0.25) -> list[tuple[int, float]]:
        """Distinct keys near any of the queries (q, DIM) within `radius` in L2, with the distance of
        their nearest row, nearest first."""
        keys, dist = self.search(queries, k)
        order = np.argsort(dist, axis=None)
        seen: dict[int, float] = {}
        for flat in order:
            key, d = int(keys.flat[flat]), float(dist.flat[flat])
            if key >= 0 and d <= radius:
                seen.setdefault(key, d)
        return list(seen.items())
