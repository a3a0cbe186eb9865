"""Ingest cost of the variant step on the realworld corpus, through the service's own code.

    python -m benchmarks.variants_ingest [--limit 40] [--max-vertices 60000] [--cached-only] [--whole-job]

Every readable realworld mesh (in name order, up to --limit) is stored in a scratch data directory,
one after the other, as uploads arrive; for each, the ingest's numerical work (parse + describe +
view mesh, services.ingestion) is timed, then services.variants.detect (fingerprints, lookup among the
models stored before it, verification of the candidates, links written), twice on identical copies
of the collection: with the cache of prepared candidate meshes, and with a cache that keeps nothing
(every candidate read and prepared afresh, as before the cache). Prints the totals and the overhead,
in wall-clock seconds and in this process's CPU seconds (on a machine shared with other work the wall
clock counts the waits; the CPU seconds are the cost). BLAS runs on one thread, as in the service's
worker processes (app/worker/processes.py): with a thread per core on a busy machine, describe's
eigensolves spin and wait, and its time (the denominator) grows several-fold.

--whole-job adds a second measure of the same step: each upload's ingest job run as the worker runs
it (services.ingestion.run_ingest: read the file, parse, describe, the variant step, write the
description, the explain geometry and the thumbnail, encode with the shipped vocabulary, mark ready),
with the variant step's share taken from the job's own timings, as an operator reads them, and that
of the step and the object rows together (each object of a multi-object file described: issue 31's
"each object indexed as a part of the file"). The first
measure's denominator is the numerical work alone and is the stricter of the two.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from pathlib import Path

from app.config import Settings
from app.core.mesh import InvalidMeshError, load_mesh
from app.datasets import locate
from app.services import ingestion, variants, vocabularies
from app.services.context import ServiceContext, open_context
from app.storage import jobs as jobs_repo
from app.worker.processes import pin_threads
from benchmarks.common import machine, table


def corpus(root: Path, limit: int, max_vertices: int) -> list[Path]:
    with open(root / "STATS.csv") as fh:
        rows = sorted(csv.DictReader(fh), key=lambda r: r["file"])
    ok = [root / r["file"] for r in rows if r["loader_result"] == "ok" and r["merged_verts"].isdigit()
          and 20 <= int(r["merged_verts"]) <= max_vertices]
    return ok[:limit]


def run(files: list[Path], ctx: ServiceContext, cached: bool) -> dict:
    variants.prepared_cache(ctx, variants.PreparedCache() if cached else variants.PreparedCache(0, 0))
    params = ctx.settings.describe.params()
    ingest_s = variant_s = ingest_cpu = variant_cpu = 0.0
    links = n = 0
    for path in files:
        data = path.read_bytes()
        try:
            model = ingestion.submit(ctx, data, path.name).model
            t, c = time.perf_counter(), time.process_time()
            mesh = load_mesh(data, model.file_type, max_vertices=ctx.settings.max_vertices)
            ingestion.describe_and_view(mesh, params)
        except (InvalidMeshError, ValueError) as exc:
            print(f"skipped {path.name}: {exc}")
            continue
        ingest_s += time.perf_counter() - t
        ingest_cpu += time.process_time() - c
        c = time.process_time()
        found, seconds = variants.timed_detect(ctx, model.id, mesh)
        variant_cpu += time.process_time() - c
        variant_s += seconds
        links += len(found)
        n += 1
    cache = variants.prepared_cache(ctx)
    return {"cache": "LRU" if cached else "none", "models": n, "parse+describe s": ingest_s,
            "variant step s": variant_s, "overhead": variant_s / ingest_s if ingest_s else float("nan"),
            "parse+describe CPU s": ingest_cpu, "variant step CPU s": variant_cpu,
            "CPU overhead": variant_cpu / ingest_cpu if ingest_cpu else float("nan"),
            "links": links, "cache hits": cache.hits, "cache misses": cache.misses}


def run_jobs(files: list[Path], ctx: ServiceContext) -> dict:
    """Each file uploaded, then its ingest job claimed and run as the worker runs it."""
    vocabularies.ensure_default(ctx)  # encode with the shipped vocabulary, as a fresh service does
    job_s = job_cpu = variant_s = objects_s = 0.0
    n = failed = 0
    for path in files:
        submitted = ingestion.submit(ctx, path.read_bytes(), path.name)
        if submitted.job_id is None:
            continue  # identical content: no job
        job = jobs_repo.claim(ctx.db, "bench", 600, 1)
        assert job is not None and job.id == submitted.job_id
        t, c = time.perf_counter(), time.process_time()
        try:
            timings = ingestion.run_ingest(ctx, job)
        except (InvalidMeshError, ValueError):
            failed += 1  # the worker fails such a job; it costs no variant step
            continue
        job_s += time.perf_counter() - t
        job_cpu += time.process_time() - c
        variant_s += timings["variants"]
        objects_s += timings.get("objects", 0.0)
        n += 1
    rest = job_s - variant_s
    both = job_s - variant_s - objects_s  # the job without the variant step and the object rows
    return {"models": n, "failed": failed, "job s": job_s, "job CPU s": job_cpu, "variant step s": variant_s,
            "overhead (step / rest of the job)": variant_s / rest if rest > 0 else float("nan"),
            "object rows s": objects_s,
            "overhead (step + object rows / the rest)":
                (variant_s + objects_s) / both if both > 0 else float("nan")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--limit", type=int, default=40, help="meshes (default 40, in name order)")
    ap.add_argument("--max-vertices", type=int, default=60_000)
    ap.add_argument("--cached-only", action="store_true", help="only the run with the cache (the service's)")
    ap.add_argument("--whole-job", action="store_true", help="also: the step's share of whole ingest jobs")
    args = ap.parse_args(argv)
    pin_threads()  # one BLAS thread, as the service's workers run an ingest: several would inflate describe
    try:
        root = locate.require("realworld")
    except locate.DatasetMissing as exc:
        print(f"variants_ingest: {exc}")
        return 2
    files = corpus(root, args.limit, args.max_vertices)
    warm = load_mesh(files[0])  # untimed: the first describe pays for imports and first-call set-up
    ingestion.describe_and_view(warm, Settings().describe.params())
    rows = []
    for cached in (True,) if args.cached_only else (True, False):
        with tempfile.TemporaryDirectory() as tmp:
            rows.append(run(files, open_context(Settings(data_dir=Path(tmp) / "data")), cached))
        print(rows[-1], flush=True)  # each run as it ends: a long one may be cut short
    title = f"ingest of {len(files)} realworld meshes, the variant step with and without the cache"
    print(table(rows, title=title))
    if args.whole_job:
        with tempfile.TemporaryDirectory() as tmp:
            whole = run_jobs(files, open_context(Settings(data_dir=Path(tmp) / "data")))
        print(table([whole], title=f"\nthe same {len(files)} uploads as whole ingest jobs (run_ingest)"))
    print(machine())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
