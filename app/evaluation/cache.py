"""Describe a whole labelled folder once: worker processes fill an on-disk cache the evaluation reads.

Cache layout (default .cache/describe, gitignored):
    <root>/<sha256(DescribeParams.fingerprint() | core code hash)[:16]>/<file sha256>[.noise<nsr>-s<seed>].npz
    <root>/d2-<bins>x<pairs>-<code hash>/<file sha256>[.noise<nsr>-s<seed>].npy
A description depends only on the mesh bytes and the parameters, so a second run with other
BoF settings (runs, vocabulary, hard/soft, keypoints-only) reads every description back and never
repeats an eigen-solve. Files are written to a temporary name and renamed, so an interrupted run
leaves no half-written entry.
"""

from __future__ import annotations

import hashlib
import io
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.baselines import D2_BINS, D2_PAIRS, d2_histogram
from app.core.mesh import InvalidMeshError, Mesh, load_mesh
from app.core.pipeline import DescribeParams, ShapeDescription, describe
from app.core.resolution import perturb
from app.core.spectrum import SpectrumError
from app.storage.blobs import atomic_write


def content_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def noise_seed(sha: str, seed: int) -> int:
    """Per-shape noise seed: fixed by the file content, so results do not depend on file order."""
    return (int(sha[:12], 16) + 1_000_003 * seed) % (2**63)


@dataclass(frozen=True)
class Variant:
    """Which version of a mesh: clean (noise 0) or perturbed with noise-to-signal `noise`."""

    noise: float = 0.0
    seed: int = 0

    def suffix(self) -> str:
        return "" if self.noise == 0 else f".noise{self.noise:g}-s{self.seed}"


# the core modules that never decide a description (they encode, rank or score one); the code of every
# other app/core module, sub-packages included, keys the cache: editing any of them (the method is
# being tuned, a module is split in two) must invalidate it, or an evaluation would silently report
# stale descriptions
_NOT_DESCRIBE = ("vocabulary", "fusion", "descriptor", "metrics", "baselines", "variants", "partial_match",
                 "piece_rank", "piece_fit")
_NOT_D2 = ("vocabulary", "fusion", "descriptor", "metrics", "laplacian", "spectrum", "hks", "keypoints",
           "pipeline", "smoothing")


def code_fingerprint(exclude: Sequence[str] = ()) -> str:
    """sha256 (16 hex) of the source of every app/core/**/*.py but the top-level modules and
    sub-packages `exclude`."""
    core = Path(__file__).resolve().parents[1] / "core"
    h = hashlib.sha256()
    for path in sorted(core.rglob("*.py")):
        top = path.relative_to(core).parts[0].removesuffix(".py")
        if top in exclude:  # a top-level module, or a whole sub-package (variants relates, never describes)
            continue
        h.update(path.relative_to(core).as_posix().encode() + b"\0" + path.read_bytes())
    return h.hexdigest()[:16]


# hashed at import, right after the core was imported: the code this process (and its forked
# workers) runs, even if a file is edited while an evaluation is under way
_FINGERPRINTS = {"describe": code_fingerprint(_NOT_DESCRIBE), "d2": code_fingerprint(_NOT_D2)}


class DescriptionCache:
    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self._describe_code = _FINGERPRINTS["describe"]
        self._d2_code = _FINGERPRINTS["d2"]

    def description_path(self, sha: str, params: DescribeParams, variant: Variant) -> Path:
        key = hashlib.sha256(f"{params.fingerprint()}|{self._describe_code}".encode()).hexdigest()[:16]
        return self.root / key / f"{sha}{variant.suffix()}.npz"

    def d2_path(self, sha: str, variant: Variant) -> Path:
        return self.root / f"d2-{D2_BINS}x{D2_PAIRS}-{self._d2_code}" / f"{sha}{variant.suffix()}.npy"


@dataclass(frozen=True)
class Task:
    """One mesh to describe. The parent resolves the cache paths (its code fingerprint is the one
    of the code that runs: workers are forked from it), so an edit made during a run cannot
    scatter entries under another key."""

    path: str
    sha: str
    params: DescribeParams
    variant: Variant
    description_path: str | None  # None: already cached
    d2_path: str | None


@dataclass
class DescribeStats:
    computed: int = 0  # descriptions computed (eigen-solves) in this run
    cached: int = 0  # descriptions read back from the cache
    d2_computed: int = 0
    seconds: float = 0.0


class DescribeFailure(Exception):
    """Some meshes of the folder could not be described; the message names them."""


def load_variant(path: str, sha: str, variant: Variant) -> Mesh:
    """The mesh of one cache entry: the file as loaded, perturbed as `variant` says (seeded by its sha)."""
    mesh = load_mesh(path)
    if variant.noise > 0:
        mesh = perturb(mesh, variant.noise, noise_seed(sha, variant.seed))
    return mesh


def run_task(task: Task) -> str | None:
    """Worker body: describe one mesh into the cache. Returns None, or an error message."""
    try:
        mesh = load_variant(task.path, task.sha, task.variant)
        if task.description_path:
            desc = describe(mesh, task.params)
            atomic_write(Path(task.description_path), desc.save)
        if task.d2_path:
            hist = d2_histogram(mesh, seed=0)
            atomic_write(Path(task.d2_path), _npy_bytes(hist))
    except (InvalidMeshError, SpectrumError, ValueError) as exc:
        return f"{task.path}: {exc}"
    return None


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=False)
    return buf.getvalue()


def _one_blas_thread() -> None:
    """Pool initializer: the pool is the parallelism; BLAS threads inside it would oversubscribe."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)


def describe_all(
    files: Sequence[tuple[Path, str]],
    params: DescribeParams,
    cache: DescriptionCache,
    variant: Variant = Variant(),
    with_d2: bool = False,
    workers: int = 2,
    progress: bool = True,
    stats: DescribeStats | None = None,
    label: str = "describe",
) -> DescribeStats:
    """Make sure the cache holds a description (and D2) of every (path, sha256) in `files`.

    workers <= 1 runs in this process (no pool), which keeps tests and debugging simple. `label` heads
    the progress line (the evaluation names the rows these descriptions are for).
    """
    from app.progress import progress as tqdm  # plain lines off a terminal

    stats = stats or DescribeStats()
    start = time.perf_counter()
    tasks = []
    for path, sha in files:
        desc_path, d2_path = cache.description_path(sha, params, variant), cache.d2_path(sha, variant)
        need_desc = not desc_path.exists()
        need_d2 = with_d2 and not d2_path.exists()
        stats.computed += need_desc
        stats.cached += not need_desc
        stats.d2_computed += need_d2
        if need_desc or need_d2:
            tasks.append(Task(str(path), sha, params, variant, str(desc_path) if need_desc else None,
                              str(d2_path) if need_d2 else None))
    label += f" (noise {variant.noise:g})" if variant.noise else ""
    errors: list[str] = []
    with tqdm(total=len(tasks), desc=label, unit="mesh", disable=not progress or not tasks) as bar:
        if workers <= 1:
            for task in tasks:
                err = run_task(task)
                errors += [err] if err else []
                bar.update()
        elif tasks:
            with ProcessPoolExecutor(max_workers=workers, initializer=_one_blas_thread) as pool:
                for fut in as_completed([pool.submit(run_task, t) for t in tasks]):
                    err = fut.result()
                    errors += [err] if err else []
                    bar.update()
    stats.seconds += time.perf_counter() - start
    if errors:
        shown = "; ".join(sorted(errors)[:5])
        more = f" (and {len(errors) - 5} more)" if len(errors) > 5 else ""
        raise DescribeFailure(f"{len(errors)} mesh(es) could not be described: {shown}{more}")
    return stats


def load_descriptions(
    files: Sequence[tuple[Path, str]], params: DescribeParams, cache: DescriptionCache, variant: Variant
) -> list[ShapeDescription]:
    return [ShapeDescription.load(cache.description_path(sha, params, variant)) for _, sha in files]


def load_d2(files: Sequence[tuple[Path, str]], cache: DescriptionCache, variant: Variant) -> np.ndarray:
    """(N, bins) D2 histograms."""
    return np.stack([np.load(cache.d2_path(sha, variant), allow_pickle=False) for _, sha in files])
