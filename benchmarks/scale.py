"""The job queue on SQLite vs PostgreSQL: `python -m benchmarks.scale [--jobs 400] [--workers 1,2,4]`.

Each run enqueues `--jobs` empty jobs and lets W worker processes claim and complete them (the same
claim + mark_done transactions a real worker runs, with no describing in between), so the figures are
the queue's own cost per job and how it holds up with more claimers. PostgreSQL is a throwaway server
from Debian's packages (tests/pg_server.py), or `--database-url` (a fresh database is created on it).
Not measured here yet: ingestion with describing, search latency through replicas (docs/deploy.md).
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
    ap.add_argument("--jobs", type=int, default=400)
    ap.add_argument("--workers", default="1,2,4")
    ap.add_argument("--repeat", type=int, default=2, help="runs per configuration; the best is kept")
    ap.add_argument("--database-url", default="", help="an existing PostgreSQL server (admin URL)")
    args = ap.parse_args(argv)
    from tests import pg_server  # the throwaway server the tests use

    rows = []
    with ExitStack() as stack, tempfile.TemporaryDirectory() as tmp:
        admin = args.database_url
        if not admin:
            os.environ.setdefault(pg_server.OPT_IN, "1")
            admin = stack.enter_context(pg_server.server())
        for workers in [int(w) for w in args.workers.split(",")]:
            for engine in ("sqlite", "postgresql"):
                runs = []
                for r in range(args.repeat):  # a fresh database each time; the best run is kept
                    data_dir = Path(tmp) / f"{engine}-{workers}-{r}"
                    url = "" if engine == "sqlite" else pg_server.fresh_database(admin)
                    runs.append(run_once(url, data_dir, args.jobs, workers))
                rows.append({"engine": engine, **max(runs, key=lambda row: row["jobs/s"])})
                print(table(rows[-1:]), flush=True)
    print(table(rows, title=f"job queue, {args.jobs} empty jobs: claim + mark_done per job"))
    write_json("scale", {"machine": machine(), "jobs": args.jobs, "rows": rows})


if __name__ == "__main__":
    main()
