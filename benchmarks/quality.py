"""Quality at a fraction of the cost: retrieval scores of ours vs plain on the same high-resolution meshes.

SHREC'11 meshes of a few classes are Loop-subdivided and simplified to ~4k vertices (a fair
high-resolution test set). Each pipeline describes every mesh (2 worker processes, one BLAS thread
each), fits its own 64-word vocabulary on its own keypoint descriptors, encodes, and ranks every mesh
against the others by L1 distance; NN/FT/ST/E/DCG/mAP as app.core.metrics defines them.
Descriptions are cached under .cache/bench/ so an interrupted run resumes.

    python -m benchmarks.quality                 # 6 classes x 20 meshes at 4k vertices (~10 min)
    python -m benchmarks.quality --short         # 5 classes x 8 meshes
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from app.core.vocabulary import EncodeParams
from benchmarks.common import THREAD_VARS, pin_threads, table, write_json
from benchmarks.realbof import CACHE, _code_key

ENCODINGS = {"default": EncodeParams(), "area-weighted": EncodeParams(area_weighted=True)}
VOCAB_SEEDS = (0, 1, 2)


def _init() -> None:
    os.environ.update({v: "1" for v in THREAD_VARS})
    pin_threads(1)


def _describe_one(job: tuple[str, int, str, str]) -> tuple[str, float]:
    """(source path, vertices, mode, cache file) -> (cache file, CPU seconds); skips cached ones."""
    src, vertices, mode, out = job
    if Path(out).exists():
        with np.load(out, allow_pickle=False) as z:
            return out, float(z["cpu"])
    from app.core.mesh import load_mesh
    from app.core.pipeline import DescribeParams, describe
    from benchmarks.meshes import upsample

    mesh = upsample(load_mesh(src), vertices)
    params = DescribeParams() if mode == "ours" else DescribeParams(target_vertices=0, solver="sparse")
    t = time.process_time()
    desc = describe(mesh, params)
    cpu = time.process_time() - t
    tmp = out + ".tmp.npz"
    np.savez(
        tmp,
        hks=desc.hks,
        weights=desc.weights,
        keypoints=desc.keypoints,
        eigenvalues=desc.eigenvalues,
        cpu=cpu,
        vertices=mesh.n_vertices,
    )
    os.replace(tmp, out)
    return out, cpu


def _load(path: str):
    from app.core.pipeline import ShapeDescription

    with np.load(path, allow_pickle=False) as z:
        return ShapeDescription(
            hks=z["hks"],
            weights=z["weights"],
            keypoints=z["keypoints"].astype(bool),
            eigenvalues=z["eigenvalues"],
            input_vertices=int(z["vertices"]),
        )


def run(classes: int, per_class: int, vertices: int = 4000, workers: int = 2, name: str = "quality") -> dict:
    from app.core.metrics import retrieval_scores
    from app.core.vocabulary import Vocabulary, l1_distance
    from benchmarks.meshes import pick

    files = pick(classes, per_class)
    labels = np.array([label for _, label in files])
    key = hashlib.sha256(f"{_code_key(files)}-{vertices}".encode()).hexdigest()[:16]
    cache = CACHE / f"quality-{key}"
    cache.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    detail: dict[str, dict] = {}
    for mode in ("ours", "plain"):
        jobs = [
            (str(p), vertices, mode, str(cache / f"{i:04d}-{mode}.npz")) for i, (p, _) in enumerate(files)
        ]
        t = time.perf_counter()
        with ProcessPoolExecutor(workers, initializer=_init) as pool:
            done = list(pool.map(_describe_one, jobs))
        wall = time.perf_counter() - t
        descs = [_load(path) for path, _ in done]
        cpu = np.array([c for _, c in done])
        for encoding, params in ENCODINGS.items():
            per_seed = []
            for seed in VOCAB_SEEDS:  # k-means is seed-dependent: average over a few vocabularies
                vocab = Vocabulary.fit(descs, size=64, seed=seed)
                bof = np.stack([vocab.encode(d, params) for d in descs])
                per_seed.append(retrieval_scores(l1_distance(bof, bof), labels))
            scores = {m: float(np.mean([sc[m] for sc in per_seed])) for m in per_seed[0]}
            rows.append(
                {
                    "pipeline": mode,
                    "encoding": encoding,
                    "meshes": len(files),
                    "vertices": vertices,
                    "solved_at": int(np.median([d.n_vertices for d in descs])),
                    "cpu_s_per_mesh": float(np.median(cpu)),
                    **scores,
                    "mAP_min": float(min(sc["mAP"] for sc in per_seed)),
                    "mAP_max": float(max(sc["mAP"] for sc in per_seed)),
                }
            )
        detail[mode] = {"wall_s_this_run": wall, "cpu_s": cpu.tolist()}
        print(table(rows[-len(ENCODINGS) :], title=f"-- {mode}"), flush=True)
    ours, plain = (
        next(r for r in rows if r["pipeline"] == m and r["encoding"] == "default") for m in ("ours", "plain")
    )
    verdict = "not worse" if ours["mAP"] >= plain["mAP"] - 1e-9 else "WORSE"
    print(
        table(
            rows,
            title=f"quality: {classes} classes x {per_class} SHREC'11 meshes at ~{vertices} vertices, "
            f"scores averaged over {len(VOCAB_SEEDS)} vocabularies; default encoding: ours/plain "
            f"mAP = {ours['mAP']:.4f}/{plain['mAP']:.4f} ({verdict}); "
            f"CPU per mesh {plain['cpu_s_per_mesh'] / ours['cpu_s_per_mesh']:.0f}x less",
        )
    )
    path = write_json(
        name,
        {
            "classes": sorted(set(labels.tolist())),
            "per_class": per_class,
            "rows": rows,
            "detail": detail,
            "verdict": verdict,
        },
    )
    print(f"wrote {path}")
    return {"rows": rows, "verdict": verdict}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--short", action="store_true", help="5 classes x 8 meshes")
    ap.add_argument("--tiny", action="store_true", help="smoke mode: 2 classes x 3 meshes at 1000 vertices")
    ap.add_argument("--classes", type=int, default=6)
    ap.add_argument("--per-class", type=int, default=20)
    ap.add_argument("--vertices", type=int, default=4000)
    args = ap.parse_args(argv)
    if args.tiny:
        run(2, 3, 1000, name="quality-tiny")
    elif args.short:
        run(5, 8, args.vertices, name="quality-short")
    else:
        suffix = "" if (args.classes, args.per_class, args.vertices) == (6, 20, 4000) else (
            f"-{args.classes}x{args.per_class}-{args.vertices}"
        )
        run(args.classes, args.per_class, args.vertices, name=f"quality{suffix}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
