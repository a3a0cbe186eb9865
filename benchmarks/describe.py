"""Describe benchmark: per-stage seconds and peak memory vs mesh size, plain vs ours, in one run.

ours  = the service pipeline: load -> clean -> resample to ~1000 vertices -> dense eigh (k=300) -> ...
plain = the same pipeline at full resolution with scipy eigsh(L, 300, M, sigma) (shift-invert ARPACK).
Every measurement runs in a fresh child process (one BLAS thread, like a worker), which reports its
own peak RSS. Stage columns are CPU seconds; `total` is wall seconds, `cpu` CPU seconds, both from
reading the file to the BoF vector; `ratio` / `ratio_cpu` = plain / ours on wall / CPU seconds.
On a shared machine the CPU figures are the stable ones (wall time includes waiting for a core).

    python -m benchmarks.describe            # 4k, 10k, 40k, 160k; plain at every size (~4 min idle)
    python -m benchmarks.describe --short    # plain only at 4k and 10k
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import REPO_ROOT, peak_rss_mb, pin_threads, table, thread_env, write_json

STAGES = ("load", "clean", "noise", "resample", "laplacian", "eigen", "hks", "keypoints", "encode")
FULL_SIZES = (4000, 10000, 40000, 160000)


class _CpuClock:
    """Stands in for the `time` module inside app.core.pipeline: its stage laps become CPU seconds."""

    perf_counter = staticmethod(time.process_time)


def measure(path: str, mode: str, vocab_dir: str, repeats: int, threads: int | None = 1) -> dict:
    """In this process: describe `path` `repeats` times; median CPU seconds per stage, total wall and
    CPU seconds, peak RSS (MiB). Stages are timed in CPU seconds, which stay meaningful on a
    shared, oversubscribed machine where wall time also counts other people's work."""
    pin_threads(threads)
    import app.core.pipeline as pipeline_mod
    from app.core import mesh as mesh_mod
    from app.core.pipeline import DescribeParams, describe
    from app.core.vocabulary import Vocabulary

    pipeline_mod.time = _CpuClock  # type: ignore[assignment]
    vocab = Vocabulary.load(vocab_dir)
    params = DescribeParams() if mode == "ours" else DescribeParams(target_vertices=0, solver="sparse")
    base_rss = peak_rss_mb()
    runs = []
    for _ in range(repeats):
        w0, t0 = time.perf_counter(), time.process_time()
        data = Path(path).read_bytes()
        vertices, faces = mesh_mod._parse(data, mesh_mod.detect_format(path))
        t1 = time.process_time()
        mesh = mesh_mod.clean(mesh_mod.validate(vertices, faces))
        t2 = time.process_time()
        desc = describe(mesh, params)
        t3 = time.process_time()
        vocab.encode(desc)
        t4 = time.process_time()
        sec = {"load": t1 - t0, "clean": t2 - t1, **desc.seconds, "encode": t4 - t3}
        sec["cpu"] = t4 - t0
        sec["total"] = time.perf_counter() - w0
        runs.append(sec)
    out = {k: statistics.median(r.get(k, 0.0) for r in runs) for k in (*STAGES, "total", "cpu")}
    out.update(
        vertices=mesh.n_vertices,
        solved_vertices=desc.n_vertices,
        repeats=repeats,
        peak_rss_mb=peak_rss_mb(),
        base_rss_mb=base_rss,
    )
    return out


def measure_in_child(path: str, mode: str, vocab_dir: str, repeats: int, threads: int | None = 1) -> dict:
    """Run `measure` in a fresh interpreter so peak RSS belongs to this measurement alone."""
    arg = json.dumps(
        {"path": path, "mode": mode, "vocab_dir": vocab_dir, "repeats": repeats, "threads": threads}
    )
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks.describe", "--child", arg],
        capture_output=True,
        text=True,
        check=False,
        env=thread_env(threads),
        cwd=REPO_ROOT,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"child failed on {path} ({mode}):\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def make_vocabulary(directory: Path, n_meshes: int = 8, size: int = 32) -> str:
    """A small vocabulary fitted on a few canonical-resolution SHREC'11 descriptions (for encode)."""
    from app.core.mesh import load_mesh
    from app.core.pipeline import describe
    from app.core.vocabulary import Vocabulary
    from benchmarks.meshes import pick

    descs = [describe(load_mesh(p)) for p, _ in pick(n_meshes, 1)]
    return str(Vocabulary.fit(descs, size=size, keypoints_only=False).save(directory / "vocab"))


def run(
    sizes: tuple[int, ...],
    plain_max: int,
    repeats: int,
    out_dir: Path | None = None,
    name: str = "describe",
    vocab_meshes: int = 8,
) -> dict:
    from app.core.mesh import load_mesh
    from benchmarks.meshes import pick, upsample, write

    tmp = Path(out_dir or tempfile.mkdtemp(prefix="shapebag-bench-"))
    vocab_dir = make_vocabulary(tmp, vocab_meshes)
    source = load_mesh(pick(1, 1)[0][0])
    rows = []
    for n in sizes:
        mesh = upsample(source, n)
        files = {fmt: str(write(mesh, tmp / f"mesh_{n}.{fmt}")) for fmt in ("ply", "obj")}
        ours = {fmt: measure_in_child(files[fmt], "ours", vocab_dir, repeats) for fmt in files}
        plain = measure_in_child(files["ply"], "plain", vocab_dir, 1) if n <= plain_max else None
        for label, res, fmt in [
            ("ours", ours["ply"], "ply"),
            ("ours", ours["obj"], "obj"),
            ("plain", plain, "ply"),
        ]:
            if res is None:
                continue
            row = {"vertices": res["vertices"], "pipeline": label, "format": fmt}
            row.update({s: res[s] for s in STAGES})
            row.update(
                total=res["total"], cpu=res["cpu"], peak_mb=res["peak_rss_mb"], base_mb=res["base_rss_mb"]
            )
            if plain is not None and label == "ours":
                row["ratio"] = plain["total"] / res["total"]
                row["ratio_cpu"] = plain["cpu"] / res["cpu"]
            rows.append(row)
        print(table(rows[-3:] if plain else rows[-2:], title=f"-- {n} vertices"), flush=True)
    cols = ["vertices", "pipeline", "format", *STAGES, "total", "cpu", "ratio", "ratio_cpu", "peak_mb"]
    print(
        table(
            rows,
            cols,
            title="describe: CPU seconds per stage (median of repeats), total wall and CPU "
            "seconds, ratio = plain/ours (wall, CPU), peak RSS MiB of the child process",
        )
    )
    path = write_json(
        name, {"sizes": list(sizes), "plain_max": plain_max, "repeats": repeats, "threads": 1, "rows": rows}
    )
    print(f"wrote {path}")
    return {"rows": rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--short", action="store_true", help="plain only up to 10k vertices")
    ap.add_argument("--tiny", action="store_true", help="smoke mode: 800 vertices, 1 repeat")
    ap.add_argument("--sizes", type=str, default=None, help="comma-separated vertex counts")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--child", type=str, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(measure(**json.loads(args.child))))
        return 0
    if args.tiny:
        run((800,), plain_max=800, repeats=1, name="describe-tiny", vocab_meshes=2)
        return 0
    sizes = tuple(int(s) for s in args.sizes.split(",")) if args.sizes else FULL_SIZES
    run(
        sizes,
        plain_max=10000 if args.short else max(sizes),
        repeats=args.repeats,
        name="describe-short" if args.short else "describe",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
