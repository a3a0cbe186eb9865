"""Bounded load on loopback: N concurrent clients for S seconds, searches and uploads mixed.

    python -m benchmarks.load                       # 50 clients, 60 s, a fresh seeded server
    python -m benchmarks.load --seconds 15 --url http://127.0.0.1:8000   # against a running server

Every upload is a new mesh (a perturbed copy of a corpus mesh), so it is stored and ingested: the
workers compete with the query pool for the same cores. Prints requests, errors and p50/p99 latency per
kind and writes results/load.json. An error is any transport failure or non-2xx answer.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from benchmarks.common import REPO_ROOT, table, write_json

SHREC = Path(
    os.environ.get("SHAPEBAG_SHREC", REPO_ROOT.parent / "shared" / "datasets" / "shrec11-simplified")
)
FAST_ENV = {
    "SHAPEBAG_DESCRIBE__K": "40",
    "SHAPEBAG_DESCRIBE__M": "20",
    "SHAPEBAG_DESCRIBE__TARGET_VERTICES": "300",
    "SHAPEBAG_DEFAULT_VOCABULARY": "",
    "SHAPEBAG_VOCABULARY_SIZE": "16",
    "SHAPEBAG_LOG_LEVEL": "WARNING",
    "SHAPEBAG_QUEUE_LIMIT": "100000",
}


def obj_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """vertices (n, 3), faces (f, 3) 0-based -> OBJ text."""
    v = "\n".join(f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices.tolist())
    f = "\n".join(f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces.tolist())
    return (v + "\n" + f + "\n").encode()


class Meshes:
    """Query meshes as they are; upload meshes as new perturbed copies (unique content each time)."""

    def __init__(self, files: list[Path], seed: int = 0) -> None:
        from app.core.mesh import load_mesh

        self.queries = [(p.name, p.read_bytes()) for p in files]
        self.arrays = [load_mesh(p) for p in files]
        self.rng = np.random.default_rng(seed)

    def query(self) -> tuple[str, bytes]:
        return self.queries[int(self.rng.integers(len(self.queries)))]

    def upload(self) -> tuple[str, bytes]:
        m = self.arrays[int(self.rng.integers(len(self.arrays)))]
        noise = self.rng.normal(scale=1e-3 * float(np.ptp(m.vertices)), size=m.vertices.shape)
        return "load.obj", obj_bytes(m.vertices + noise, m.faces)


async def drive(
    base: str,
    meshes: Meshes,
    clients: int = 50,
    seconds: float = 60.0,
    upload_share: float = 0.2,
    seed: int = 0,
) -> dict:
    """Run the load; returns {kind: {requests, errors, p50_s, p99_s}} plus error samples and totals."""
    lat: dict[str, list[float]] = {"search": [], "upload": []}
    errors: dict[str, int] = {"search": 0, "upload": 0}
    samples: list[str] = []
    pick = random.Random(seed)
    deadline = time.monotonic() + seconds
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)

    async with httpx.AsyncClient(base_url=base, timeout=300, limits=limits) as http:

        async def client() -> None:
            while time.monotonic() < deadline:
                kind = "upload" if pick.random() < upload_share else "search"
                name, data = meshes.upload() if kind == "upload" else meshes.query()
                route = "/models" if kind == "upload" else "/search"
                t = time.perf_counter()
                try:
                    r = await http.post(route, files={"file": (name, data)})
                    ok = 200 <= r.status_code < 300
                    detail = f"{r.status_code} {r.text[:120]}"
                except httpx.HTTPError as exc:
                    ok, detail = False, f"{type(exc).__name__}: {exc}"
                lat[kind].append(time.perf_counter() - t)
                if not ok:
                    errors[kind] += 1
                    if len(samples) < 10:
                        samples.append(f"{route}: {detail}")

        t0 = time.perf_counter()
        await asyncio.gather(*(client() for _ in range(clients)))
        wall = time.perf_counter() - t0
    out: dict = {"clients": clients, "seconds": seconds, "wall_s": wall, "error_samples": samples}
    for kind, values in lat.items():
        v = np.asarray(values) if values else np.zeros(1)
        out[kind] = {
            "requests": len(values),
            "errors": errors[kind],
            "p50_s": float(np.percentile(v, 50)),
            "p99_s": float(np.percentile(v, 99)),
            "max_s": float(v.max()),
        }
    out["requests"] = sum(len(v) for v in lat.values())
    out["errors"] = sum(errors.values())
    out["throughput_rps"] = out["requests"] / wall
    return out


def report(result: dict) -> str:
    rows = [{"kind": k, **result[k]} for k in ("search", "upload")]
    text = table(
        rows,
        ["kind", "requests", "errors", "p50_s", "p99_s", "max_s"],
        title=f"load: {result['clients']} clients for {result['seconds']:g} s "
        f"({result['throughput_rps']:.1f} requests/s, {result['errors']} errors)",
    )
    return text + "".join(f"  error: {s}\n" for s in result["error_samples"])


def corpus_files(n: int = 16) -> list[Path]:
    """n SHREC'11 meshes (one per class first), else a small synthetic corpus."""
    if (SHREC / "labels.csv").is_file():
        import csv

        with open(SHREC / "labels.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        by_class: dict[str, list[str]] = {}
        for row in rows:
            by_class.setdefault(row["class"], []).append(row["file"])
        picked = [files[i] for i in range(3) for files in by_class.values() if i < len(files)][:n]
        return [SHREC / f for f in picked]
    from app.datasets.synthetic import generate

    root = Path(generate(Path(tempfile.mkdtemp(prefix="shapebag-load-")), classes=4, per_class=4, seed=0))
    return sorted(root.rglob("*.obj"))[:n]


def seed_data_dir(data_dir: Path, files: list[Path]) -> None:
    """Ingest `files` and fit a vocabulary, in this process (the FAST_ENV settings)."""
    os.environ.update(FAST_ENV)
    from app.config import Settings
    from app.services import ingestion
    from app.services.context import open_context
    from app.storage import jobs as jobs_repo
    from app.worker.runner import Worker

    ctx = open_context(Settings(data_dir=data_dir, dev_mode=True))
    for p in files:
        ingestion.submit(ctx, p.read_bytes(), p.name, label=p.parent.parent.name)
    worker = Worker(ctx, "load-seed")
    worker.run_forever(exit_when_idle=True)
    with ctx.db.write() as conn:
        jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={})
    worker.run_forever(exit_when_idle=True)


def serve(data_dir: Path, workers: int) -> tuple[subprocess.Popen, str]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = dict(
        os.environ,
        **FAST_ENV,
        SHAPEBAG_DATA_DIR=str(data_dir),
        SHAPEBAG_ADMIN_TOKEN="load-test",
        SHAPEBAG_WORKERS=str(workers),
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--port", str(port)],
        env=env,
        cwd=REPO_ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    base = f"http://127.0.0.1:{port}"
    for _ in range(600):
        try:
            if httpx.get(f"{base}/readyz", timeout=2).status_code == 200:
                return proc, base
        except httpx.TransportError:
            pass
        if proc.poll() is not None:
            break
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    raise SystemExit("the server did not become ready")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--upload-share", type=float, default=0.2, help="fraction of requests that upload")
    ap.add_argument("--workers", type=int, default=1, help="embedded workers of the started server")
    ap.add_argument("--url", default=None, help="drive a running server instead of starting one")
    args = ap.parse_args(argv)
    files = corpus_files()
    meshes = Meshes(files)
    proc = None
    with tempfile.TemporaryDirectory(prefix="shapebag-load-") as tmp:
        base = args.url
        if base is None:
            seed_data_dir(Path(tmp) / "data", files)
            proc, base = serve(Path(tmp) / "data", args.workers)
        try:
            result = asyncio.run(drive(base, meshes, args.clients, args.seconds, args.upload_share))
        finally:
            if proc is not None:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(60)
    print(report(result))
    write_json("load", result)
    return 0 if result["errors"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
