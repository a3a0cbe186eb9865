"""Variants within a collection: look each mesh's fingerprints up among the others', verify the few
nearest, and group the meshes that are variants of one another."""

from __future__ import annotations

import numpy as np

from app.core.variants.gate import RADIUS
from app.core.variants.index import FingerprintIndex
from app.core.variants.prepared import Prepared
from app.core.variants.relate import Evidence, relate

K = 32  # neighbours asked of the index per fingerprint (a model's whole and each of its objects)
VERIFY = 5  # candidates verified per model, nearest first ...
SURE = 0.05  # ... and every one this close, however many (one part on many plates), up to MAX_SURE
MAX_SURE = 32


def fingerprints(p: Prepared) -> np.ndarray:
    """(1 + objects, DIM) float32: the whole surface, then each object of a multi-object mesh."""
    return np.array([p.fingerprint] + [q.fingerprint for q in p.parts if q is not p])


def build_index(items: list[Prepared]) -> FingerprintIndex:
    keys, vectors = [], []
    for i, p in enumerate(items):
        f = fingerprints(p)
        keys += [i] * len(f)
        vectors.append(f)
    index = FingerprintIndex()
    if items:
        index.build(np.array(keys), np.concatenate(vectors))
    return index


def shortlist(index: FingerprintIndex, queries: np.ndarray, exclude: int | None = None) -> list[int]:
    """The models worth verifying for a model with these fingerprints (queries (q, DIM))."""
    found = [(k, d) for k, d in index.nearest(queries, k=K, radius=RADIUS) if k != exclude]
    sure = [k for k, d in found if d <= SURE][:MAX_SURE]
    rest = [k for k, d in found if d > SURE]
    return sure + rest[: max(0, VERIFY - len(sure))]


def find_pairs(items: list[Prepared]) -> list[tuple[int, int, Evidence]]:
    """(i, j, relation of i to j) for every verified pair i < j that is more than `similar`."""
    index = build_index(items)
    done: set[tuple[int, int]] = set()
    out = []
    for i, p in enumerate(items):
        for j in shortlist(index, fingerprints(p), exclude=i):
            pair = (min(i, j), max(i, j))
            if pair in done:
                continue
            done.add(pair)
            ev = relate(items[pair[0]], items[pair[1]])
            if ev.relation != "similar":
                out.append((pair[0], pair[1], ev))
    return out


def groups(n: int, pairs: list[tuple[int, int, Evidence]]) -> list[list[int]]:
    """Connected groups (of 2 or more) of the variant graph, each sorted, in order of first member."""
    parent = list(range(n))

    def root(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for i, j, _ in pairs:
        parent[root(i)] = root(j)
    members: dict[int, list[int]] = {}
    for x in range(n):
        members.setdefault(root(x), []).append(x)
    return sorted((m for m in members.values() if len(m) > 1), key=lambda m: m[0])
