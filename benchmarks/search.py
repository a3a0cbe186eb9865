"""Search benchmark: flat FAISS L1 (IndexFlat, METRIC_L1) vs ApproxL1Index (IVF-Flat, L1) vs size.

Vectors: the 600 real SHREC'11 BoF vectors plus realistic synthetic ones made from them
(benchmarks.realbof.augment). Queries: 200 held-out synthetic vectors, and the 600 real vectors.
Latency is one query at a time (what a request does), one thread; recall@10 is against the flat
index's answer. One row per index and nprobe.

    python -m benchmarks.search            # 1e4, 1e5, 1e6 vectors
    python -m benchmarks.search --short    # 1e4, 1e5
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import numpy as np

from benchmarks.common import pin_threads, table, write_json

K = 10


def recall_at(got: np.ndarray, want: np.ndarray) -> float:
    """Mean |got ∩ want| / k over the query rows (k = want.shape[1])."""
    return float(np.mean([len(set(a) & set(b)) / want.shape[1] for a, b in zip(got, want, strict=True)]))


def latency_ms(index, queries: np.ndarray) -> tuple[float, float]:
    """p50, p95 of single-query search times in ms."""
    times = []
    for q in queries:
        t = time.perf_counter()
        index.search(q[None], K)
        times.append((time.perf_counter() - t) * 1e3)
    return float(np.percentile(times, 50)), float(np.percentile(times, 95))


def real_only_recall(real: np.ndarray) -> list[dict]:
    """IVF trained on the 600 real vectors alone; every real vector queries it (itself included)."""
    from app.index.approximate import ApproxL1Index
    from app.index.faiss_l1 import FaissL1Index

    ids = np.arange(len(real), dtype=np.int64)
    flat, approx = FaissL1Index(real.shape[1]), ApproxL1Index(real.shape[1], train_at=1)
    flat.add(ids, real)
    approx.add(ids, real)
    approx.wait_for_training()
    _, want = flat.search(real, K)
    rows = []
    for nprobe in (None, 16, 32):
        approx.nprobe = nprobe
        _, got = approx.search(real, K)
        rows.append(
            {
                "vectors": len(real),
                "nlist": approx._index.nlist,
                "nprobe": nprobe or f"default ({_nprobe(approx)})",
                "recall@10": recall_at(got, want),
            }
        )
    return rows


def _nprobe(index) -> int:
    from app.index.approximate import default_nprobe

    return index.nprobe or default_nprobe(index._index.nlist)


def run(
    sizes: tuple[int, ...], n_queries: int = 200, name: str = "search", real_limit: int | None = None
) -> dict:
    import faiss

    from app.index.approximate import ApproxL1Index
    from app.index.faiss_l1 import FaissL1Index
    from benchmarks.realbof import augment, shrec_bof

    faiss.omp_set_num_threads(1)
    pin_threads(1)  # k-means training runs BLAS: one thread, as in a worker (see throughput.py)
    t = time.perf_counter()
    real, _ = shrec_bof(limit=real_limit)
    print(f"{len(real)} real BoF vectors ready in {time.perf_counter() - t:.1f} s", flush=True)
    real_rows = real_only_recall(real)
    print(table(real_rows, title="recall@10 of the IVF index on the real SHREC'11 BoF vectors alone"))
    queries = augment(real, n_queries, seed=99)
    rows = []
    for n in sizes:
        base = np.concatenate([real, augment(real, max(0, n - len(real)), seed=n)])[:n]
        ids = np.arange(n, dtype=np.int64)
        built: dict[str, tuple[Any, float]] = {}
        for label, index in (("flat", FaissL1Index(64)), ("ivf", ApproxL1Index(64))):
            t = time.perf_counter()
            for s in range(0, n, 100_000):  # add in batches, as an ingestion backlog would
                index.add(ids[s : s + 100_000], base[s : s + 100_000])
            if isinstance(index, ApproxL1Index):
                index.wait_for_training()  # the IVF builds in a background thread
            built[label] = (index, time.perf_counter() - t)
        flat, flat_build = built["flat"]
        _, want_syn = flat.search(queries, K)
        _, want_real = flat.search(real, K)
        p50, p95 = latency_ms(flat, queries)
        rows.append(
            {
                "vectors": n,
                "index": "flat",
                "nprobe": "-",
                "build_s": flat_build,
                "p50_ms": p50,
                "p95_ms": p95,
                "recall@10": 1.0,
                "recall@10_real": 1.0,
                "memory_mb": n * 64 * 4 / 2**20,
            }
        )
        approx, approx_build = built["ivf"]
        base_nprobe = _nprobe(approx) if approx.approximate else 0
        for nprobe in sorted({base_nprobe, 2 * base_nprobe, 4 * base_nprobe}):
            approx.nprobe = nprobe or None
            _, got_syn = approx.search(queries, K)
            _, got_real = approx.search(real, K)
            p50, p95 = latency_ms(approx, queries)
            kind = "ivf" if approx.approximate else "ivf (exact: below train_at)"
            rows.append(
                {
                    "vectors": n,
                    "index": kind,
                    "nprobe": nprobe or "-",
                    "build_s": approx_build,
                    "p50_ms": p50,
                    "p95_ms": p95,
                    "recall@10": recall_at(got_syn, want_syn),
                    "recall@10_real": recall_at(got_real, want_real),
                    "memory_mb": n * 64 * 4 / 2**20,
                }
            )
            if not approx.approximate:
                break
        approx.nprobe = None
        print(table(rows[-4:], title=f"-- {n} vectors"), flush=True)
        del built, flat, approx
    print(
        table(
            rows,
            title="search: single-query latency (1 thread), recall@10 vs flat "
            "(synthetic queries; the 600 real vectors as queries)",
        )
    )
    path = write_json(
        name, {"sizes": list(sizes), "queries": n_queries, "k": K, "real_only": real_rows, "rows": rows}
    )
    print(f"wrote {path}")
    return {"rows": rows, "real_only": real_rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--short", action="store_true", help="1e4 and 1e5 vectors only")
    ap.add_argument("--tiny", action="store_true", help="smoke mode: 60 real meshes, 2000 vectors")
    ap.add_argument("--sizes", type=str, default=None, help="comma-separated vector counts")
    args = ap.parse_args(argv)
    if args.tiny:
        run((2000,), n_queries=20, name="search-tiny", real_limit=60)
        return 0
    sizes: tuple[int, ...] = (10_000, 100_000) if args.short else (10_000, 100_000, 1_000_000)
    if args.sizes:
        sizes = tuple(int(float(s)) for s in args.sizes.split(","))
    run(sizes, name="search-short" if args.short else "search")
    return 0


if __name__ == "__main__":
    sys.exit(main())
