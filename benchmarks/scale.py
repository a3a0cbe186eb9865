"""SQLite vs PostgreSQL, 1/2/4 workers: `python -m benchmarks.scale [--parts queue,ingest,search]`.

queue: each run enqueues `--jobs` empty jobs and lets W worker processes claim and complete them (the same
claim + mark_done transactions a real worker runs, with no describing in between), so the figures are
the queue's own cost per job and how it holds up with more claimers. PostgreSQL is a throwaway server
from Debian's packages (tests/pg_server.py), or `--database-url` (a fresh database is created on it).

ingest: `--meshes` SHREC'11 meshes described, stored and encoded by W worker processes (scale_ingest.py).
search: p50/p95 of searches through 1 vs 2 API processes (`shapebag serve --processes`) on PostgreSQL.
Results: docs/performance.md and docs/deploy.md; JSON under results/scale.json.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from app.storage import jobs as jobs_repo
from app.storage.engine import open_database
from benchmarks import scale_ingest
from benchmarks.common import machine, table, write_json

CTX = multiprocessing.get_context("spawn")


def _claimer(url: str, data_dir: str, name: str, barrier: Any, done: Any) -> None:
    db = open_database(Path(data_dir), url)
    barrier.wait()
    n = 0
    while (job := jobs_repo.claim(db, name, lease_seconds=600, max_attempts=3)) is not None:
        with db.write() as conn:
            jobs_repo.mark_done(conn, job.id, {})
        n += 1
    done.put(n)


def run_once(url: str, data_dir: Path, jobs: int, workers: int) -> dict:
    db = open_database(data_dir, url)
    db.migrate()
    with db.write() as conn:
        for _ in range(jobs):
            jobs_repo.enqueue(conn, "ingest")
    barrier, done = CTX.Barrier(workers + 1), CTX.Queue()
    args = [(url, str(data_dir), f"w{i}", barrier, done) for i in range(workers)]
    procs = [CTX.Process(target=_claimer, args=a) for a in args]
    for p in procs:
        p.start()
    barrier.wait()  # every worker has started and opened its database: time the queue alone
    t = time.perf_counter()
    counts = [done.get(timeout=900) for _ in procs]
    seconds = time.perf_counter() - t
    for p in procs:
        p.join()
    assert sum(counts) == jobs, f"{sum(counts)} of {jobs} jobs done"
    per_job_ms = 1000 * seconds * workers / jobs  # wall time a worker spends on one job's two transactions
    return {"workers": workers, "jobs/s": jobs / seconds, "ms/job per worker": per_job_ms}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", default="queue,ingest,search", help="which measurements, comma-separated")
    ap.add_argument("--jobs", type=int, default=400, help="queue: empty jobs per run")
    ap.add_argument("--workers", default="1,2,4")
    ap.add_argument("--repeat", type=int, default=2, help="queue: runs per configuration; the best is kept")
    ap.add_argument("--meshes", type=int, default=40, help="ingest: SHREC'11 meshes per run")
    ap.add_argument("--queries", type=int, default=40, help="search: searches per configuration")
    ap.add_argument("--clients", type=int, default=4, help="search: concurrent clients")
    ap.add_argument("--dataset", type=Path, default=scale_ingest.DATASET)
    ap.add_argument("--database-url", default="", help="an existing PostgreSQL server (admin URL)")
    args = ap.parse_args(argv)
    parts = set(args.parts.split(","))
    worker_counts = [int(w) for w in args.workers.split(",")]
    from tests import pg_server  # the throwaway server the tests use

    out: dict = {"machine": machine(), "jobs": args.jobs, "meshes": args.meshes}
    with ExitStack() as stack, tempfile.TemporaryDirectory() as tmp:
        admin = args.database_url
        if not admin:
            os.environ.setdefault(pg_server.OPT_IN, "1")
            admin = stack.enter_context(pg_server.server())
        if "queue" in parts:
            rows = []
            for workers in worker_counts:
                for engine in ("sqlite", "postgresql"):
                    runs = []
                    for r in range(args.repeat):  # a fresh database each time; the best run is kept
                        data_dir = Path(tmp) / f"{engine}-{workers}-{r}"
                        url = "" if engine == "sqlite" else pg_server.fresh_database(admin)
                        runs.append(run_once(url, data_dir, args.jobs, workers))
                    rows.append({"engine": engine, **max(runs, key=lambda row: row["jobs/s"])})
                    print(table(rows[-1:]), flush=True)
            print(table(rows, title=f"job queue, {args.jobs} empty jobs: claim + mark_done per job"))
            out["queue"] = rows
        files = scale_ingest.meshes(args.dataset, args.meshes + args.queries)
        corpus, queries = files[: args.meshes], [p for p, _ in files[args.meshes :]]
        filled = ""  # a PostgreSQL database the ingestion filled, for the search part
        if "ingest" in parts or "search" in parts:
            rows = []
            counts = worker_counts if "ingest" in parts else [max(worker_counts)]
            for workers in counts:
                for engine in ("sqlite", "postgresql"):
                    data_dir = Path(tmp) / f"ingest-{engine}-{workers}"
                    url = "" if engine == "sqlite" else pg_server.fresh_database(admin)
                    rows.append(
                        {"engine": engine, **scale_ingest.ingest_once(data_dir, url, corpus, workers)}
                    )
                    print(table(rows[-1:]), flush=True)
                    filled = url or filled
            print(table(rows, title=f"ingestion, {len(corpus)} SHREC'11 meshes described + stored + encoded"))
            out["ingest"] = rows
        if "search" in parts:
            rows = []
            for processes in (1, 2):
                data_dir = Path(tmp) / f"search-{processes}"  # a new host: its cache starts empty
                rows.append(
                    scale_ingest.search_latency(
                        data_dir, filled, queries, processes, args.clients, len(corpus)
                    )
                )
                print(table(rows[-1:]), flush=True)
            print(table(rows, title=f"search on PostgreSQL, {len(corpus)} models, {args.clients} clients"))
            out["search"] = rows
    write_json("scale", out)


if __name__ == "__main__":
    main()
