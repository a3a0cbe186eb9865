"""L1 nearest-neighbour indexes over BoF vectors (see base.ShapeIndex)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from app.index.approximate import ApproxL1Index
from app.index.base import IndexFileError, ShapeIndex
from app.index.faiss_l1 import FaissL1Index
from app.index.numpy_l1 import NumpyL1Index

BACKENDS: dict[str, Any] = {"faiss": FaissL1Index, "numpy": NumpyL1Index, "approx": ApproxL1Index}
FILE_NAMES = {"faiss": "index.faiss", "numpy": "index.npz", "approx": "index-ivf.faiss"}


def new_index(backend: str, dim: int) -> ShapeIndex:
    if backend not in BACKENDS:
        raise ValueError(f"unknown index backend {backend!r}; use one of {', '.join(BACKENDS)}")
    return BACKENDS[backend](dim)


def load_index(backend: str, path: Path) -> ShapeIndex:
    return BACKENDS[backend].load(path)


__all__ = [
    "ApproxL1Index",
    "BACKENDS",
    "FILE_NAMES",
    "FaissL1Index",
    "IndexFileError",
    "NumpyL1Index",
    "ShapeIndex",
    "load_index",
    "new_index",
]
