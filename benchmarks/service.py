"""Service benchmark: a real server (uvicorn, embedded workers) on a loopback port over a temp data dir.

1. ingest N SHREC'11 meshes at 10k vertices over HTTP (POST /models), time until all are ready:
   ingestion meshes/minute with the server's 2 embedded worker processes;
2. fill the index to `fill` models: synthetic BoF vectors made from the ingested models' real vectors
   (benchmarks.realbof.augment) are written as ready models + vectors in the service's database, and
   the running server's index follows the database as it does for ingested models (ingesting 100k
   meshes would take hours on 2 cores);
3. POST /search with 10k-vertex query meshes (not in the index) from 1, 8 and 32 concurrent httpx
   clients, a bounded number of requests each: client-side p50/p95 latency, plus the server's own
   split (describe vs search).

    python -m benchmarks.service                       # N=24, fill 100k, flat FAISS index
    python -m benchmarks.service --short               # N=16, fill 10k
    python -m benchmarks.service --index-backend approx
"""

from __future__ import annotations

import argparse
import asyncio
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from benchmarks.common import REPO_ROOT, table, write_json

CONCURRENCY = {1: 12, 8: 32, 32: 64}  # clients -> requests sent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_server(
    data_dir: Path, port: int, backend: str, log_path: Path, workers: int = 2,
    overrides: dict[str, str] | None = None,
) -> subprocess.Popen:
    """`shapebag serve` on data_dir; `overrides` replaces settings of the environment below (a
    benchmark of refusals passes the served defaults of the per-client bound and the queue back)."""
    env = dict(
        os.environ,
        SHAPEBAG_DATA_DIR=str(data_dir),
        SHAPEBAG_PORT=str(port),
        SHAPEBAG_DEV_MODE="1",
        SHAPEBAG_WORKERS=str(workers),
        SHAPEBAG_SEARCH_PROCESSES="2",
        SHAPEBAG_INDEX_BACKEND=backend,
        SHAPEBAG_AUTO_VOCABULARY_MIN_MODELS="16",
        SHAPEBAG_POLL_INTERVAL_S="0.2",
        # the query load stands for many users from one loopback address: the per-client bound and the
        # queue's 503 (issue 20) would refuse it by design, and this measures capacity, not refusal
        SHAPEBAG_CLIENT_REQUESTS="64",
        SHAPEBAG_SEARCH_QUEUE="64",
        SHAPEBAG_CLIENT_UPLOADS="64",
    )
    env.update(overrides or {})
    log = open(log_path, "wb")  # noqa: SIM115 (the server process owns it until it exits)
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "app.cli",
            "serve",
            "--data-dir",
            str(data_dir),
            "--port",
            str(port),
            "--workers",
            str(workers),
            "--dev",
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
        env=env,
        cwd=REPO_ROOT,
    )
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"server exited ({proc.returncode}); see {log_path}")
        try:
            if httpx.get(f"{base}/healthz", timeout=2).status_code == 200:
                return proc
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    proc.terminate()
    raise RuntimeError(f"server did not answer /healthz in 120 s; see {log_path}")


def stop_server(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def wait_until(check, timeout_s: float, what: str, every_s: float = 0.5):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(every_s)
    raise RuntimeError(f"timed out after {timeout_s:.0f} s waiting for {what}")


def ingest(base: str, files: list[tuple[str, str]]) -> dict:
    """Upload every file, wait until each model is ready (or failed); meshes per minute."""
    t0 = time.perf_counter()
    ids = []
    with httpx.Client(base_url=base, timeout=60) as client:
        for path, label in files:
            with open(path, "rb") as fh:
                r = client.post(
                    "/models",
                    files={"file": (Path(path).name, fh.read())},
                    data={"name": Path(path).stem, "label": label},
                )
            r.raise_for_status()
            ids.append(r.json()["model_id"])
        upload_s = time.perf_counter() - t0

        def all_done():
            states = [client.get(f"/models/{i}").json()["status"] for i in ids]
            return states if all(s in ("ready", "failed") for s in states) else None

        states = wait_until(all_done, 1800, "ingestion", every_s=0.5)
    wall = time.perf_counter() - t0
    ready = states.count("ready")
    return {
        "meshes": len(files),
        "ready": ready,
        "failed": states.count("failed"),
        "upload_s": upload_s,
        "wall_s": wall,
        "meshes_per_min": 60.0 * ready / wall,
    }


def fill_index(data_dir: Path, target: int, seed: int = 0) -> int:
    """Write synthetic ready models + BoF vectors (active vocabulary) until `target` models have one."""
    from app.config import Settings
    from app.services.context import open_context
    from app.storage import models as models_repo
    from app.storage import vocabularies as vocab_repo
    from benchmarks.realbof import augment

    ctx = open_context(Settings(data_dir=data_dir, dev_mode=True))
    with ctx.db.read() as conn:
        record = vocab_repo.active(conn)
        if record is None:
            raise RuntimeError("the service has no active vocabulary to fill the index for")
        _, real, _ = vocab_repo.vectors(conn, record.id)
    missing = target - len(real)
    if missing <= 0:
        return 0
    synthetic = augment(real, missing, seed=seed)
    for s in range(0, missing, 20_000):
        with ctx.db.write() as conn:
            for i, vec in enumerate(synthetic[s : s + 20_000], start=s):
                mid = models_repo.insert(
                    conn,
                    name=f"synthetic-{i}",
                    label=None,
                    metadata={"synthetic": True},
                    sha256=f"synthetic-{seed}-{i:08d}",
                    file_type="ply",
                    size_bytes=0,
                )
                models_repo.set_ready(conn, mid, 10_000)
                vocab_repo.put_vector(conn, mid, record.id, vec)
    return missing


async def _query_load(base: str, queries: list[bytes], names: list[str], clients: int, total: int) -> dict:
    latencies, server = [], []
    refused: dict[int, int] = {}  # status -> count: the queue's 503 past its deadline is an answer too
    sem = asyncio.Semaphore(clients)
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    async with httpx.AsyncClient(base_url=base, timeout=300, limits=limits) as client:

        async def one(i: int) -> None:
            async with sem:
                t = time.perf_counter()
                r = await client.post(
                    "/search",
                    files={"file": (names[i % len(names)], queries[i % len(queries)])},
                    data={"k": "10"},
                )
                if r.status_code in (429, 503):
                    refused[r.status_code] = refused.get(r.status_code, 0) + 1
                    return
                r.raise_for_status()
                latencies.append(time.perf_counter() - t)
                server.append(r.json().get("seconds", {}))

        t0 = time.perf_counter()
        await asyncio.gather(*(one(i) for i in range(total)))
        wall = time.perf_counter() - t0
    lat = np.array(latencies) if latencies else np.array([np.nan])
    return {
        "clients": clients,
        "requests": total,
        "refused": sum(refused.values()),
        "p50_s": float(np.percentile(lat, 50)),
        "p95_s": float(np.percentile(lat, 95)),
        "max_s": float(lat.max()),
        "queries_per_s": len(latencies) / wall,
        "server_describe_p50_s": float(np.median([s.get("describe", np.nan) for s in server])),
        "server_search_p50_s": float(np.median([s.get("search", s.get("index", np.nan)) for s in server])),
    }


def run(
    n_ingest: int,
    fill: int,
    backend: str = "faiss",
    vertices: int = 10_000,
    concurrency: dict[int, int] | None = None,
    name: str = "service",
) -> dict:
    from app.core.mesh import load_mesh
    from benchmarks.meshes import pick, upsample, write

    concurrency = concurrency or CONCURRENCY
    tmp = Path(tempfile.mkdtemp(prefix="shapebag-service-"))
    chosen = pick(30, 2)  # 2 per class: the first of each class is ingested first, queries are the rest
    ingest_src = (chosen[0::2] + chosen[1::2])[:n_ingest]
    query_src = [c for c in chosen if c not in ingest_src][:8] or chosen[:4]
    files = [
        (str(write(upsample(load_mesh(p), vertices), tmp / "in" / f"{i:03d}.ply")), label)
        for i, (p, label) in enumerate(ingest_src)
    ]
    qfiles = [
        str(write(upsample(load_mesh(p), vertices), tmp / "q" / f"q{i:02d}.ply"))
        for i, (p, _) in enumerate(query_src)
    ]
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    log = tmp / "server.log"
    proc = start_server(tmp / "data", port, backend, log)
    try:
        ing = ingest(base, files)
        print(
            table([ing], title=f"ingestion over HTTP at {vertices} vertices, 2 embedded workers"), flush=True
        )
        wait_until(lambda: httpx.get(f"{base}/readyz", timeout=10).status_code == 200, 300, "a vocabulary")
        t = time.perf_counter()
        added = fill_index(tmp / "data", fill)
        fill_s = time.perf_counter() - t
        indexed = wait_until(
            lambda: (
                (n := httpx.get(f"{base}/readyz", timeout=30).json()["checks"]["indexed_models"]) >= fill
                and n
            ),
            600,
            f"{fill} indexed models",
            every_s=1.0,
        )
        print(
            f"index filled: {added} synthetic models written in {fill_s:.1f} s; {indexed} indexed", flush=True
        )
        queries = [Path(q).read_bytes() for q in qfiles]
        names = [Path(q).name for q in qfiles]
        # warm-up, not recorded: the query pool spawns its processes (imports) on first use
        asyncio.run(_query_load(base, queries, names, 2, 4))
        rows = []
        for clients, total in concurrency.items():
            rows.append(asyncio.run(_query_load(base, queries, names, clients, total)))
            print(table(rows[-1:]), flush=True)
    finally:
        stop_server(proc)
    print(
        table(
            rows,
            title=f"POST /search, {vertices}-vertex query meshes, {indexed} indexed models "
            f"({backend} index), 2 query processes",
        )
    )
    path = write_json(
        name,
        {
            "vertices": vertices,
            "backend": backend,
            "indexed": indexed,
            "synthetic_fill": added,
            "ingestion": ing,
            "queries": rows,
            "server_log": str(log),
        },
    )
    print(f"wrote {path}")
    return {"ingestion": ing, "queries": rows, "indexed": indexed}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--short", action="store_true", help="16 meshes, 10k indexed, fewer requests")
    ap.add_argument("--tiny", action="store_true", help="smoke mode: 16 meshes at 1k vertices, 100 indexed")
    ap.add_argument("--ingest", type=int, default=24)
    ap.add_argument("--fill", type=int, default=100_000)
    ap.add_argument("--index-backend", default="faiss")
    args = ap.parse_args(argv)
    if args.tiny:
        run(16, 100, args.index_backend, vertices=1000, concurrency={1: 2, 4: 4}, name="service-tiny")
    elif args.short:
        run(16, 10_000, args.index_backend, concurrency={1: 8, 8: 16, 32: 32}, name="service-short")
    else:
        run(args.ingest, args.fill, args.index_backend)
    return 0


if __name__ == "__main__":
    sys.exit(main())
