"""Ingestion with describing, and search latency through 1 vs 2 API processes (python -m benchmarks.scale).

Ingestion: real meshes (SHREC'11) are submitted first (the upload's store + queue, no HTTP), then W worker
processes (`shapebag worker --exit-when-idle`'s loop: claim, describe, store, encode, mark done) drain the
queue; the clock runs from a barrier all workers passed to the last job done. SQLite uses the data dir's
file and filesystem blobs (one host); PostgreSQL the database blob backend (nothing shared but the server).

Search: `shapebag serve --processes P` over the database that ingestion filled, each process with one
query-describing process (SHAPEBAG_SEARCH_PROCESSES=1), so P is the number of replicas; C client threads
send the same number of searches (each a query mesh upload) on fresh connections; p50/p95 per request.
"""

from __future__ import annotations

import csv
import multiprocessing
import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

CTX = multiprocessing.get_context("spawn")
DATASET = Path(__file__).resolve().parents[2] / "shared" / "datasets" / "shrec11-simplified"


def meshes(root: Path, n: int) -> list[tuple[Path, str]]:
    """n meshes spread over the classes (round robin), in a fixed order."""
    by_class: dict[str, list[Path]] = {}
    with open(root / "labels.csv", newline="") as fh:
        for row in csv.DictReader(fh):
            by_class.setdefault(row["class"], []).append(root / row["file"])
    lists = [sorted(v) for _, v in sorted(by_class.items())]
    out: list[tuple[Path, str]] = []
    i = 0
    while len(out) < n and any(i < len(v) for v in lists):
        out += [(v[i], v[i].parent.name) for v in lists if i < len(v)]
        i += 1
    return out[:n]


def settings_for(data_dir: Path, url: str) -> Any:
    from app.config import Settings

    backend = "database" if url else "filesystem"
    return Settings(data_dir=data_dir, database_url=url, blob_backend=backend, workers=0, warm_up=False)


def _ingester(settings_json: str, name: str, barrier: Any, done: Any) -> None:
    from app.worker.processes import pin_threads

    pin_threads()
    from app.config import Settings
    from app.services.context import open_context
    from app.worker.runner import Worker

    ctx = open_context(Settings.model_validate_json(settings_json))
    worker = Worker(ctx, name)
    barrier.wait()
    done.put((worker.run_forever(exit_when_idle=True), time.perf_counter()))


def ingest_once(data_dir: Path, url: str, files: list[tuple[Path, str]], workers: int) -> dict:
    from app.services import ingestion, vocabularies
    from app.services.context import open_context
    from app.storage import models as models_repo

    settings = settings_for(data_dir, url)
    ctx = open_context(settings)
    vocabularies.ensure_default(ctx)  # the shipped vocabulary: each job also encodes its BoF
    for path, label in files:
        ingestion.submit(ctx, path.read_bytes(), path.name, path.stem, label)
    barrier, done = CTX.Barrier(workers + 1), CTX.Queue()
    procs = [
        CTX.Process(target=_ingester, args=(settings.model_dump_json(), f"bench-{i}", barrier, done))
        for i in range(workers)
    ]
    for p in procs:
        p.start()
    barrier.wait()
    t = time.perf_counter()
    results = [done.get(timeout=1800) for _ in procs]
    seconds = max(end for _, end in results) - t
    for p in procs:
        p.join()
    with ctx.db.read() as conn:
        status = models_repo.count_by_status(conn)
    assert sum(n for n, _ in results) == len(files) and status["ready"] == len(files), (results, status)
    return {"workers": workers, "meshes": len(files), "seconds": seconds, "meshes/s": len(files) / seconds}


def search_latency(
    data_dir: Path, url: str, queries: list[Path], processes: int, clients: int, models: int
) -> dict:
    import httpx

    from benchmarks.service import free_port, stop_server

    port = free_port()
    base = f"http://127.0.0.1:{port}"
    env = {
        **os.environ,
        "SHAPEBAG_DATABASE_URL": url,
        "SHAPEBAG_BLOB_BACKEND": "database" if url else "filesystem",
        "SHAPEBAG_SEARCH_PROCESSES": "1",
        "SHAPEBAG_ADMIN_TOKEN": "bench-token-kkkkkkkkkkkkkkkkkkkk",
        "SHAPEBAG_LOG_LEVEL": "WARNING",
    }
    cmd = [
        sys.executable,
        "-m",
        "app.cli",
        "serve",
        "--data-dir",
        str(data_dir),
        "--port",
        str(port),
        "--processes",
        str(processes),
        "--workers",
        "0",
    ]
    log = data_dir.with_name(data_dir.name + ".log")
    proc = subprocess.Popen(cmd, env=env, stdout=log.open("wb"), stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120

        def indexed() -> int:  # /readyz is 503 here (no worker runs): its checks say what is loaded
            return int(httpx.get(f"{base}/readyz", timeout=5).json()["checks"]["indexed_models"])

        while True:  # every process up with every model indexed (fresh connections land on either)
            try:
                if all(indexed() == models for _ in range(4 * processes)):
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                tail = log.read_text(errors="replace")[-2000:]
                raise RuntimeError(
                    f"serve --processes {processes}: {models} models not indexed in 120 s\n{tail}"
                )
            time.sleep(0.5)

        def one(path: Path) -> float:
            t = time.perf_counter()
            r = httpx.post(
                f"{base}/search",
                files={"file": (path.name, path.read_bytes())},
                data={"k": "10"},
                timeout=120,
            )
            r.raise_for_status()
            return time.perf_counter() - t

        for q in queries[: 2 * processes]:  # warm each process's describer
            one(q)
        t = time.perf_counter()
        with ThreadPoolExecutor(clients) as pool:
            lat = sorted(pool.map(one, queries))
        wall = time.perf_counter() - t
    finally:
        stop_server(proc)
    q = statistics.quantiles(lat, n=20)
    return {
        "api processes": processes,
        "clients": clients,
        "searches": len(lat),
        "p50 ms": 1000 * statistics.median(lat),
        "p95 ms": 1000 * q[18],
        "searches/s": len(lat) / wall,
    }
