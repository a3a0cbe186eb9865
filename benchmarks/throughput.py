"""Ingestion throughput at 10k vertices: meshes/minute with 1 and 2 worker processes, BLAS pinned or not.

Each worker runs what an ingestion job computes (load -> clean -> describe -> encode) on 10k-vertex
PLY files. "threads=1" is what app.worker does (one BLAS thread per process); "threads=default"
lets OpenBLAS start a thread per core in every process, which oversubscribes the cores as soon as
two workers run side by side.

    python -m benchmarks.throughput            # 24 meshes per configuration
    python -m benchmarks.throughput --short    # 10 meshes per configuration
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from benchmarks.common import THREAD_VARS, pin_threads, table, write_json

_VOCAB = None


def _init(threads: int | None, vocab_dir: str) -> None:
    global _VOCAB
    if threads is not None:
        os.environ.update({v: str(threads) for v in THREAD_VARS})
    pin_threads(threads)
    from app.core.vocabulary import Vocabulary

    _VOCAB = Vocabulary.load(vocab_dir)


def _ingest(path: str) -> float:
    from app.core.mesh import load_mesh
    from app.core.pipeline import describe

    t = time.perf_counter()
    _VOCAB.encode(describe(load_mesh(path)))  # type: ignore[union-attr]
    return time.perf_counter() - t


def measure(files: list[str], workers: int, threads: int | None, vocab_dir: str) -> dict:
    with ProcessPoolExecutor(workers, initializer=_init, initargs=(threads, vocab_dir)) as pool:
        list(pool.map(_ingest, files[:workers]))  # warm: imports and first-call costs off the clock
        t = time.perf_counter()
        per_mesh = list(pool.map(_ingest, files))
        wall = time.perf_counter() - t
    return {
        "workers": workers,
        "blas_threads": threads or "default",
        "meshes": len(files),
        "wall_s": wall,
        "meshes_per_min": 60.0 * len(files) / wall,
        "s_per_mesh_in_worker": sorted(per_mesh)[len(per_mesh) // 2],
    }


def run(n_meshes: int, vertices: int = 10_000, name: str = "throughput") -> dict:
    from app.core.mesh import load_mesh
    from benchmarks.describe import make_vocabulary
    from benchmarks.meshes import pick, upsample, write

    tmp = Path(tempfile.mkdtemp(prefix="shapebag-throughput-"))
    vocab_dir = make_vocabulary(tmp, 4)
    sources = pick(30, 1)[:n_meshes]
    files = [
        str(write(upsample(load_mesh(p), vertices), tmp / f"{i:03d}.ply")) for i, (p, _) in enumerate(sources)
    ]
    while len(files) < n_meshes:
        files += files[: n_meshes - len(files)]
    rows = []
    for workers, threads in ((1, 1), (2, 1), (1, None), (2, None)):
        rows.append(measure(files, workers, threads, vocab_dir))
        print(table(rows[-1:]), flush=True)
    print(
        table(
            rows,
            title=f"ingestion throughput at {vertices} vertices (load -> describe -> encode), "
            f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}",
        )
    )
    path = write_json(name, {"vertices": vertices, "rows": rows})
    print(f"wrote {path}")
    return {"rows": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--short", action="store_true", help="10 meshes per configuration")
    ap.add_argument("--meshes", type=int, default=24)
    ap.add_argument("--tiny", action="store_true", help="smoke mode: 2 meshes at 1000 vertices")
    args = ap.parse_args(argv)
    if args.tiny:
        run(2, vertices=1000, name="throughput-tiny")
    else:
        run(10 if args.short else args.meshes, name="throughput-short" if args.short else "throughput")
    return 0


if __name__ == "__main__":
    sys.exit(main())
