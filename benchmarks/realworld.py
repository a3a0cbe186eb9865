"""Every file of the realworld corpus through the upload path, one process per file, one BLAS thread.

    python -m benchmarks.realworld                        # every file, one at a time, 60 s each
    python -m benchmarks.realworld --files 'oded__*'      # a glob on the file (or folder) name
    python -m benchmarks.realworld --jobs 2 --timeout 120
    python -m benchmarks.realworld --baseline            # with the agg=3-only simplify of before
    python -m benchmarks.realworld --target-vertices 2000 --name realworld-2k   # price another setting
    python -m benchmarks.realworld --smoothing-weights area --name realworld-area   # or another weighting
    python -m benchmarks.realworld --smoothing 12 --smoothing-weights capped-area --name realworld-c12

Each file runs in a fresh child (`OMP/OPENBLAS/MKL_NUM_THREADS=1` in its environment, so set before
numpy loads): `mesh_policy.load_upload` (load + validate + clean + surface check, the service's vertex
limit), then `pipeline.describe` with the default `DescribeParams()`. A `gltf_*` folder (a .gltf with
its .bin beside it) is sent as a .zip of the folder, as a user would upload it. The outcome is one of
described / refused (InvalidMeshError: its message is what a user reads) / error (any other exception:
a bug) / crash (the child died) / timeout. Prints the table and the distribution of describe seconds
and writes results/realworld.json.
"""

from __future__ import annotations

import argparse
import fnmatch
import io
import json
import subprocess
import sys
import time
import zipfile
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from app.datasets import locate
from benchmarks.common import REPO_ROOT, peak_rss_mb, table, thread_env, write_json

CORPUS = locate.dataset_dir("realworld")  # SHAPEBAG_DATASETS/realworld
NOT_MESHES = {"README.md", "SOURCES.csv", "STATS.csv"}
OUTCOMES = ("described", "refused", "error", "crash", "timeout")
TOLERANCE = 1.5  # the canonical-resolution band of resolution.to_resolution


def own_peak_mb() -> float:
    """This process's peak RSS in MiB since its exec (VmHWM): ru_maxrss would carry over the parent's
    peak at fork, which is large when the parent has just generated a 2M-vertex mesh."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return peak_rss_mb()


def legacy_simplify(mesh, target_vertices: int, tolerance: float = 1.5, prefilter_length: float = 0.0,
                    prefilter_ramp: tuple[float, float] = (0.0, 0.0), max_passes: int = 3):
    """resolution.simplify before issue 10 (agg=3 only, at the mesh's own scale, no low-pass): the
    baseline. Same signature as resolution.simplify, whose caller passes the low-pass and its ramp."""
    import fast_simplification
    import numpy as np

    from app.core.mesh import Mesh, clean

    v, f = mesh.vertices.astype(np.float32), mesh.faces.astype(np.int32)
    for _ in range(max_passes):
        reduction = 1.0 - min(1.0, target_vertices / len(v))
        v, f = fast_simplification.simplify(v, f, target_reduction=reduction, agg=3)
        if len(v) <= 1.1 * target_vertices:
            break
    return clean(Mesh(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)))


def use_legacy_simplify() -> None:
    """Make describe() use legacy_simplify (in a child process only)."""
    from app.core import resolution

    resolution.simplify = legacy_simplify


def corpus_entries(root: Path = CORPUS, patterns: Sequence[str] = ("*",)) -> list[Path]:
    """Files and gltf_* folders of the corpus whose name matches one of `patterns`, sorted by name."""
    entries = [p for p in root.iterdir() if p.name not in NOT_MESHES and not p.name.startswith(".")]
    picked = (p for p in entries if any(fnmatch.fnmatch(p.name, pat) for pat in patterns))
    return sorted(picked, key=lambda p: p.name)


def upload_of(entry: Path) -> tuple[bytes, str]:
    """(bytes, file name) as a user would upload `entry`: a folder becomes a .zip of its files."""
    if not entry.is_dir():
        return entry.read_bytes(), entry.name
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for f in sorted(entry.iterdir()):
            zf.write(f, f.name)
    return buf.getvalue(), f"{entry.name}.zip"


def decimation_quality(before, after, samples: int = 20000) -> dict:
    """Shape kept by the resampling: area ratio, and the symmetric Hausdorff and mean distances
    between `samples` random surface points of each mesh, as % of the input's bounding-box diagonal.
    Sampled: distances below ~0.5 % of the diagonal are the sampling's own spacing."""
    import numpy as np
    import trimesh
    from scipy.spatial import cKDTree

    def points(mesh, seed: int):
        tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
        return trimesh.sample.sample_surface(tm, samples, seed=seed)[0]

    pa, pb = points(before, 0), points(after, 1)
    d = np.concatenate([cKDTree(pb).query(pa)[0], cKDTree(pa).query(pb)[0]])
    diag = float(np.linalg.norm(np.ptp(before.vertices, axis=0)))
    return {"area_ratio": after.area() / before.area(), "hausdorff_pct": 100 * float(d.max()) / diag,
            "mean_dist_pct": 100 * float(d.mean()) / diag}


def describe_upload(entry: str, baseline: bool = False, overrides: dict | None = None) -> dict:
    """In this (child) process: the upload path on one corpus entry; never raises.

    overrides: DescribeParams fields to change (e.g. {"target_vertices": 2000}), to price a setting.
    """
    from app.config import Settings
    from app.core.mesh import InvalidMeshError
    from app.core.pipeline import DescribeParams, describe
    from app.services.mesh_policy import load_upload

    if baseline:
        use_legacy_simplify()

    params = DescribeParams(**(overrides or {}))
    max_vertices = Settings.model_fields["max_vertices"].default
    data, name = upload_of(Path(entry))
    out: dict = {"target": params.target_vertices}
    t0 = time.perf_counter()
    try:
        mesh = load_upload(data, name, max_vertices)
        out["load_s"] = time.perf_counter() - t0
        out["vertices_in"] = mesh.n_vertices
        t1, c1 = time.perf_counter(), time.process_time()
        desc = describe(mesh, params)
        out["describe_s"] = time.perf_counter() - t1
        out["describe_cpu_s"] = time.process_time() - c1  # what an idle core would take (one thread)
        out.update(outcome="described", vertices_solved=desc.n_vertices, stages=desc.seconds)
        if mesh.n_vertices > TOLERANCE * params.target_vertices:  # decimated: how much shape it kept
            from app.core.resolution import to_resolution

            out.update(decimation_quality(mesh, to_resolution(mesh, params.target_vertices)))
    except InvalidMeshError as exc:
        out.update(outcome="refused", message=str(exc))
    except Exception as exc:  # a bug, not a refusal: reported as such
        out.update(outcome="error", message=f"{type(exc).__name__}: {exc}"[:300])
    out["peak_rss_mb"] = own_peak_mb()
    return out


def run_child(entry: Path, timeout_s: float, baseline: bool = False, overrides: dict | None = None) -> dict:
    """describe_upload(entry) in a fresh one-thread interpreter; classifies deaths and timeouts."""
    t0 = time.perf_counter()
    row: dict = {"file": entry.name}
    child = ["--child", str(entry)] + (["--baseline"] if baseline else [])
    child += [f"--{key.replace('_', '-')}={value}" for key, value in (overrides or {}).items()]
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "benchmarks.realworld", *child],
            capture_output=True, text=True, check=False, env=thread_env(1), cwd=REPO_ROOT, timeout=timeout_s,
        )
    except subprocess.TimeoutExpired:
        row.update(outcome="timeout", message=f"no answer within {timeout_s:g} s")
    else:
        lines = proc.stdout.strip().splitlines()
        if proc.returncode == 0 and lines:
            row.update(json.loads(lines[-1]))
        else:
            tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
            row.update(outcome="crash", message=f"exit code {proc.returncode}: {tail}"[:300])
    row["wall_s"] = time.perf_counter() - t0
    return row


def percentile(values: list[float], q: float) -> float:
    """Linear-interpolated percentile (numpy's default), without importing numpy in the parent."""
    if not values:
        return float("nan")
    s = sorted(values)
    pos = (len(s) - 1) * q / 100.0
    lo = int(pos)
    hi = min(lo + 1, len(s) - 1)
    return s[lo] + (s[hi] - s[lo]) * (pos - lo)


def distribution(values: list[float]) -> dict[str, float]:
    """p50, p90, p95 and max of `values`."""
    return {f"p{q}": percentile(values, q) for q in (50, 90, 95)} | {"max": max(values, default=0.0)}


def _line(d: dict[str, float]) -> str:
    return ", ".join(f"{k} {v:.3f}" for k, v in d.items())


def summarise(rows: list[dict]) -> dict:
    """Outcome counts, describe-second percentiles, files solved outside the canonical band."""
    described = [r for r in rows if r["outcome"] == "described"]
    seconds = [r["describe_s"] for r in described]
    cpu = [r["describe_cpu_s"] for r in described]
    decimated = [r for r in described if "area_ratio" in r]
    above = [r["file"] for r in described if r["vertices_solved"] > TOLERANCE * r["target"]]
    below = [r["file"] for r in described if r["vertices_solved"] * TOLERANCE < r["target"]]
    return {
        "files": len(rows),
        "counts": {o: sum(r["outcome"] == o for r in rows) for o in OUTCOMES},
        "describe_s": distribution(seconds),
        "describe_cpu_s": distribution(cpu),
        "slowest": max(described, key=lambda r: r["describe_s"])["file"] if described else None,
        "solved_above_band": above,
        "solved_below_band": below,
        "max_peak_rss_mb": max((r.get("peak_rss_mb", 0.0) for r in rows), default=0.0),
        "decimated": {
            "files": len(decimated),
            "area_ratio_min": min((r["area_ratio"] for r in decimated), default=float("nan")),
            "area_ratio_max": max((r["area_ratio"] for r in decimated), default=float("nan")),
            "hausdorff_pct": distribution([r["hausdorff_pct"] for r in decimated]),
            "mean_dist_pct": distribution([r["mean_dist_pct"] for r in decimated]),
        },
    }


def report(rows: list[dict], summary: dict) -> str:
    cols = ["file", "outcome", "vertices_in", "vertices_solved", "load_s", "describe_s", "describe_cpu_s",
            "peak_rss_mb", "area_ratio", "hausdorff_pct", "mean_dist_pct"]
    text = table(rows, cols, title="realworld: upload path per file (one process, one thread)")
    messages = [r for r in rows if r["outcome"] != "described"]
    if messages:
        text += "\nnot described:\n" + "".join(
            f"  {r['file']}: {r['outcome']}: {r.get('message', '')}\n" for r in messages
        )
    counts = ", ".join(f"{k} {v}" for k, v in summary["counts"].items())
    text += (
        f"\n{summary['files']} files: {counts}\n"
        f"describe seconds: {_line(summary['describe_s'])} (slowest: {summary['slowest']})\n"
        f"describe CPU seconds: {_line(summary['describe_cpu_s'])}\n"
        f"solved above {TOLERANCE:g}x the target: {len(summary['solved_above_band'])} "
        f"{summary['solved_above_band'] or ''}\n"
        f"solved below the target / {TOLERANCE:g}: {len(summary['solved_below_band'])} "
        f"{summary['solved_below_band'] or ''}\n"
        f"largest child peak RSS: {summary['max_peak_rss_mb']:.0f} MiB\n"
    )
    q = summary["decimated"]
    if q["files"]:
        text += (
            f"decimated files: {q['files']}; area ratio {q['area_ratio_min']:.3f} to "
            f"{q['area_ratio_max']:.3f}\n"
            f"  sampled Hausdorff distance, % of the diagonal: {_line(q['hausdorff_pct'])}\n"
            f"  mean distance, % of the diagonal: {_line(q['mean_dist_pct'])}\n"
        )
    return text


def run(
    entries: list[Path], jobs: int = 1, timeout_s: float = 60.0, name: str = "realworld",
    baseline: bool = False, overrides: dict | None = None,
) -> dict:
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        rows = list(pool.map(lambda e: run_child(e, timeout_s, baseline, overrides), entries))
    summary = summarise(rows)
    print(report(rows, summary))
    simplify = "legacy (agg=3 only)" if baseline else "ours"
    path = write_json(name, {"corpus": str(CORPUS), "jobs": jobs, "timeout_s": timeout_s,
                             "simplify": simplify, "overrides": overrides or {},
                             "summary": summary, "rows": rows})
    print(f"wrote {path}")
    return {"rows": rows, "summary": summary}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--files", action="append", help="glob on the corpus file or folder name (repeatable)")
    ap.add_argument("--jobs", type=int, default=1, help="children at once (the machine is shared)")
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds per file")
    ap.add_argument("--baseline", action="store_true", help="describe with the agg=3-only simplify of before")
    ap.add_argument("--name", default=None, help="results/<name>.json (realworld, realworld-baseline)")
    ap.add_argument("--target-vertices", type=int, default=None,
                    help="canonical resolution (default: the shipped one)")
    ap.add_argument("--k", type=int, default=None, help="eigenpairs (default: the shipped k)")
    ap.add_argument("--smoothing", type=int, default=None, help="Taubin steps (default: the shipped count)")
    ap.add_argument("--smoothing-weights", default=None,
                    help="Taubin weights, one of app.core.smoothing.WEIGHTS (default: the shipped ones)")
    ap.add_argument("--smoothing-target", type=float, default=None,
                    help="adaptive smoothing's roughness target (default: the shipped one; 0: fixed steps)")
    ap.add_argument("--antialias", type=float, default=None,
                    help="low-pass before decimation, in canonical edge lengths (default: the shipped one)")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    keys = ("target_vertices", "k", "smoothing", "smoothing_weights", "smoothing_target", "antialias")
    overrides = {key: value for key in keys
                 if (value := getattr(args, key)) is not None}
    if args.child:
        print(json.dumps(describe_upload(args.child, args.baseline, overrides)))
        return 0
    from app.core.pipeline import DescribeParams  # here, not at the top: the children import it themselves

    try:  # a setting DescribeParams refuses is the command's error, not one per file
        DescribeParams(**overrides)
    except ValueError as exc:
        print(f"realworld: {exc}")
        return 2
    if not CORPUS.is_dir():
        print(f"realworld: {locate.missing_reason('realworld')}")
        return 1
    patterns = args.files or ["*"]
    entries = corpus_entries(CORPUS, patterns)
    if not entries:
        print(f"no corpus entry matches {patterns}")
        return 1
    name = args.name or ("realworld-baseline" if args.baseline else "realworld")
    result = run(entries, args.jobs, args.timeout, name, args.baseline, overrides)
    bad = sum(result["summary"]["counts"][o] for o in ("error", "crash", "timeout"))
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
