"""Huge uploads: realworld meshes midpoint-subdivided to ~200k, ~500k and ~2M vertices (the vertex limit),
loaded and described in a fresh one-thread child each; seconds per stage and the child's peak RSS.

    python -m benchmarks.large_inputs                    # the four sizes below, ours only
    python -m benchmarks.large_inputs --baseline         # + the agg=3-only simplify of before, same run
    python -m benchmarks.large_inputs --sizes 200k,500k  # a subset (labels of SIZES)

The meshes are generated in a temporary folder (binary PLY, float32 coordinates, as exporters write
them) and deleted afterwards; nothing is committed. Each child reads the file's bytes and runs the
upload path (`mesh_policy.load_upload`, then `pipeline.describe` with the default DescribeParams).
`resample` is describe's decimation stage; `*_cpu_s` are CPU seconds (what an idle core would
take: on a shared machine, wall time also counts other people's work). Peak RSS is the child's own
(VmHWM), interpreter and imports included (`base_mb`: the same child's peak before it reads the
file). A 50 MiB upload limit (`max_upload_bytes`) is not applied here: the file sizes are printed.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import REPO_ROOT, table, thread_env, write_json
from benchmarks.realworld import CORPUS, own_peak_mb, use_legacy_simplify

# label -> (corpus file, midpoint subdivisions): sizes land near the label (each step ~4x vertices)
SIZES: dict[str, tuple[str, int]] = {
    "200k": ("oded__koala.obj", 1),  # 50k closed -> 200k
    "500k": ("oded__hammer.obj", 2),  # 30k closed -> 481k
    "2M": ("oded__hammer.obj", 3),  # -> 1.92M, just under the 2,000,000 limit
    "1.6M-open": ("oded__mountain.obj", 3),  # 25.6k open terrain (636 boundary edges) -> 1.64M
}


def make(label: str, folder: Path) -> Path:
    """Subdivide the corpus file of `label` and write it as binary PLY; returns the path."""
    import trimesh

    from app.core.mesh import load_mesh

    name, steps = SIZES[label]
    mesh = load_mesh(CORPUS / name)
    v, f = mesh.vertices, mesh.faces
    for _ in range(steps):
        v, f = trimesh.remesh.subdivide(v, f)
    path = folder / f"{label}.ply"
    trimesh.Trimesh(v.astype(np.float32), f, process=False).export(path, file_type="ply", encoding="binary")
    return path


def measure(path: str, baseline: bool) -> dict:
    """In this (child) process: read, load_upload, describe; seconds, vertices, peak RSS."""
    from app.config import Settings
    from app.core.pipeline import DescribeParams, describe
    from app.services.mesh_policy import load_upload

    if baseline:
        use_legacy_simplify()
    base = own_peak_mb()
    t0, c0 = time.perf_counter(), time.process_time()
    data = Path(path).read_bytes()
    mesh = load_upload(data, Path(path).name, Settings.model_fields["max_vertices"].default)
    del data
    t1, c1 = time.perf_counter(), time.process_time()
    load_rss = own_peak_mb()
    desc = describe(mesh, DescribeParams())
    t2, c2 = time.perf_counter(), time.process_time()
    return {
        "load_cpu_s": c1 - c0,
        "describe_cpu_s": c2 - c1,
        "vertices_in": mesh.n_vertices,
        "vertices_solved": desc.n_vertices,
        "load_s": t1 - t0,
        "resample_s": desc.seconds.get("resample", 0.0),
        "eigen_s": desc.seconds.get("eigen", 0.0),
        "describe_s": t2 - t1,
        "total_s": t2 - t0,
        "base_mb": base,
        "load_peak_mb": load_rss,
        "peak_mb": own_peak_mb(),
    }


def run_child(path: Path, baseline: bool, timeout_s: float) -> dict:
    arg = json.dumps({"path": str(path), "baseline": baseline})
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "benchmarks.large_inputs", "--child", arg],
            capture_output=True, text=True, check=False, env=thread_env(1), cwd=REPO_ROOT, timeout=timeout_s,
        )
    except subprocess.TimeoutExpired:
        return {"outcome": f"timeout ({timeout_s:g} s)"}
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
        return {"outcome": f"failed (exit {proc.returncode}): {tail[:200]}"}
    return {"outcome": "described", **json.loads(lines[-1])}


def run(labels: list[str], baseline: bool, timeout_s: float, name: str) -> dict:
    rows = []
    with tempfile.TemporaryDirectory(prefix="shapebag-large-") as tmp:
        for label in labels:
            path = make(label, Path(tmp))
            size_mb = path.stat().st_size / 2**20
            for simplifier in ("legacy", "ours") if baseline else ("ours",):
                row = {"size": label, "source": SIZES[label][0], "file_mb": size_mb, "simplify": simplifier}
                row.update(run_child(path, simplifier == "legacy", timeout_s))
                rows.append(row)
                print(table([row], title=f"-- {label} ({simplifier})"), flush=True)
            path.unlink()
    cols = ["size", "simplify", "file_mb", "vertices_in", "vertices_solved", "load_s", "load_cpu_s",
            "resample_s", "eigen_s", "describe_s", "describe_cpu_s", "total_s", "base_mb", "load_peak_mb",
            "peak_mb", "outcome"]
    title = "large inputs: wall and CPU seconds (one BLAS thread; stages wall) and child peak RSS in MiB"
    print(table(rows, cols, title=title))
    path = write_json(name, {"sizes": {k: SIZES[k] for k in labels}, "threads": 1, "rows": rows})
    print(f"wrote {path}")
    return {"rows": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default=",".join(SIZES), help=f"comma-separated, of: {', '.join(SIZES)}")
    ap.add_argument("--baseline", action="store_true", help="also run the agg=3-only simplify of before")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per child")
    ap.add_argument("--name", default="large_inputs", help="results/<name>.json")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(measure(**json.loads(args.child))))
        return 0
    labels = [s.strip() for s in args.sizes.split(",") if s.strip()]
    unknown = [s for s in labels if s not in SIZES]
    if unknown:
        ap.error(f"unknown sizes {unknown}; choose from {', '.join(SIZES)}")
    result = run(labels, args.baseline, args.timeout, args.name)
    return 0 if all(r["outcome"] == "described" for r in result["rows"]) else 1


if __name__ == "__main__":
    sys.exit(main())
