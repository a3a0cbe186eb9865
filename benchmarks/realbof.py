"""Real BoF vectors of the 600 SHREC'11 meshes, and realistic synthetic ones made from them.

The 600 meshes are described at the canonical resolution in 2 worker processes (one BLAS thread
each), a 64-word vocabulary is fitted on their keypoint descriptors, and each is encoded; the result
is cached under .cache/bench/ (gitignored) keyed by the core code, so later runs take no time.
"""

from __future__ import annotations

import hashlib
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import THREAD_VARS, pin_threads
from benchmarks.meshes import labelled_files

CACHE = Path(os.environ.get("SHAPEBAG_BENCH_CACHE", ".cache/bench"))


def _describe(path: str):
    from app.core.mesh import load_mesh
    from app.core.pipeline import describe

    return describe(load_mesh(path))


def _init() -> None:
    os.environ.update({v: "1" for v in THREAD_VARS})
    pin_threads(1)


def _code_key(files: list[tuple[Path, str]]) -> str:
    import app.core

    h = hashlib.sha256()
    core = Path(app.core.__file__).parent
    for name in ("mesh", "laplacian", "spectrum", "hks", "keypoints", "pipeline", "vocabulary", "descriptor"):
        h.update((core / f"{name}.py").read_bytes())
    h.update("\n".join(str(p) for p, _ in files).encode())
    return h.hexdigest()[:16]


def shrec_bof(limit: int | None = None, workers: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """(n, 64) float32 BoF vectors (rows sum to 1) and (n,) class labels of the SHREC'11 meshes."""
    files = labelled_files()
    if limit:
        files = files[:: max(1, len(files) // limit)][:limit]
    path = CACHE / f"shrec-bof-{_code_key(files)}.npz"
    if path.exists():
        with np.load(path, allow_pickle=False) as z:
            return z["bof"], z["labels"]
    from app.core.vocabulary import Vocabulary

    with ProcessPoolExecutor(workers, initializer=_init) as pool:
        descs = list(pool.map(_describe, [str(p) for p, _ in files], chunksize=8))
    vocab = Vocabulary.fit(descs, size=64)
    bof = np.stack([vocab.encode(d) for d in descs]).astype(np.float32)
    labels = np.array([label for _, label in files])
    CACHE.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, bof=bof, labels=labels)
    tmp.rename(path)
    return bof, labels


def augment(
    real: np.ndarray, n: int, seed: int = 0, concentration: float = 30.0, max_mix: float = 0.5
) -> np.ndarray:
    """(n, v) synthetic BoF vectors that look like real ones.

    Each is a histogram resampled around a real vector (Dirichlet with mean = that vector and
    `concentration` ~ the number of independent votes), blended with a second real vector by a
    weight in [0, max_mix] (shapes between two known ones). Rows sum to 1, like real BoF. The
    defaults spread the vectors widely (a pessimistic case for an IVF index: with concentration 300
    and max_mix 0.3 every recall@10 in the search benchmark was 1.00).
    """
    rng = np.random.default_rng(seed)
    out = np.empty((n, real.shape[1]), dtype=np.float32)
    step = 50_000
    for s in range(0, n, step):
        m = min(step, n - s)
        a = real[rng.integers(0, len(real), m)].astype(np.float64)
        b = real[rng.integers(0, len(real), m)].astype(np.float64)
        g = rng.gamma(concentration * a + 0.02)  # Dirichlet(concentration * a + ε) by normalised gammas
        y = g / g.sum(axis=1, keepdims=True)
        w = rng.uniform(0.0, max_mix, (m, 1))
        out[s : s + m] = (1.0 - w) * y + w * b
    return out
