"""Bounded load on loopback: N concurrent clients for S seconds, searches and uploads mixed.

    python -m benchmarks.load                       # 50 clients, 60 s, a fresh seeded server
    python -m benchmarks.load --seconds 15 --url http://127.0.0.1:8000   # against a running server

Every upload is a new mesh (a perturbed copy of a corpus mesh), so it is stored and ingested: the
workers compete with the query pool for the same cores. Prints requests, errors and p50/p99 latency per
kind and writes results/load.json. An error is any transport failure or non-2xx answer, except a 503
or 429 with Retry-After (admission control shedding load, or the bound per client: counted as `shed`,
and the client waits as told).

It also prints the peak RSS (VmHWM, sampled every 0.25 s so restarted processes count too) of the API
process and of each worker / query-pool process, first under the hostile phase (every case of the
bad-input corpus to /models, /search and /web/preview.png, thumbnails at every size), then under load.
Goal (issue 12): the API process under 1 GB whatever the input, each child under its RLIMIT_AS cap.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import random
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np

from app.datasets import locate
from benchmarks.common import REPO_ROOT, table, write_json

SHREC = locate.dataset_dir("shrec11-simplified")  # SHAPEBAG_DATASETS/shrec11-simplified
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
    shed: dict[str, int] = {"search": 0, "upload": 0}
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
                    ok, detail, r = False, f"{type(exc).__name__}: {exc}", None
                if r is not None and r.status_code in (429, 503) and "retry-after" in r.headers:
                    shed[kind] += 1  # admission control: not an error; back off as the server asks
                    # + 0.5 s: past uvicorn's 5 s keep-alive, so a connection it is closing is never reused
                    await asyncio.sleep(float(r.headers["retry-after"]) + 0.5)
                    continue
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
            "shed": shed[kind],
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
        ["kind", "requests", "errors", "shed", "p50_s", "p99_s", "max_s"],
        title=f"load: {result['clients']} clients for {result['seconds']:g} s "
        f"({result['throughput_rps']:.1f} requests/s, {result['errors']} errors)",
    )
    return text + "".join(f"  error: {s}\n" for s in result["error_samples"])


class PeakRss:
    """Samples VmHWM (peak resident set, kB) of a server and its descendants in a background thread;
    the peak per process survives the process (a restarted pool process is a new pid)."""

    def __init__(self, pid: int, data_dir: Path | None, interval_s: float = 0.25) -> None:
        self.pid, self.data_dir, self.interval_s = pid, data_dir, interval_s
        self.peak_kb: dict[int, int] = {}
        self.role: dict[int, str] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> PeakRss:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.sample()

    def _run(self) -> None:
        while not self._stop.wait(self.interval_s):
            self.sample()

    def sample(self) -> None:
        workers = self._worker_pids()
        for pid in [self.pid, *_descendants(self.pid)]:
            try:
                status = Path(f"/proc/{pid}/status").read_text()
                cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
            except OSError:
                continue
            hwm = next((int(line.split()[1]) for line in status.splitlines() if line.startswith("VmHWM")), 0)
            self.peak_kb[pid] = max(self.peak_kb.get(pid, 0), hwm)
            if pid == self.pid:
                self.role[pid] = "api"
            elif b"resource_tracker" in cmdline:
                self.role[pid] = "resource tracker"
            elif pid in workers:
                self.role[pid] = "worker"
            else:
                self.role.setdefault(pid, "query pool")

    def _worker_pids(self) -> set[int]:
        if self.data_dir is None:
            return set()
        try:
            conn = sqlite3.connect(f"file:{self.data_dir / 'shapebag.db'}?mode=ro", uri=True, timeout=1)
            try:
                return {int(r[0]) for r in conn.execute("SELECT pid FROM workers")}
            finally:
                conn.close()
        except sqlite3.Error:
            return set()

    def summary(self) -> dict:
        """{role: {"processes": n, "peak_mb": max over them}}."""
        out: dict[str, dict] = {}
        for pid, kb in self.peak_kb.items():
            row = out.setdefault(self.role.get(pid, "?"), {"processes": 0, "peak_mb": 0.0})
            row["processes"] += 1
            row["peak_mb"] = max(row["peak_mb"], round(kb / 1024, 1))
        return out


def _descendants(pid: int) -> list[int]:
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            children.setdefault(int(stat[stat.rfind(")") + 2 :].split()[1]), []).append(int(entry.name))
    out, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out


def hostile(base: str) -> dict:
    """Every bad-input corpus case to /models, /search and /web/preview.png, bad metadata, then each
    thumbnail size of a few models: returns {status code: count} (5xx would be a bug)."""
    from tests.reliability.corpus import bad_metadata, build
    from tests.reliability.helpers import MULTIPART_HEADERS, multipart  # exact bytes, as a client could send

    codes: dict[str, int] = {}

    def count(method: str, url: str, **kwargs) -> None:
        try:
            key = str(http.request(method, url, **kwargs).status_code)
        except (httpx.HTTPError, ValueError, TypeError):  # a case this client cannot even send
            key = "not sent"
        codes[key] = codes.get(key, 0) + 1

    with httpx.Client(base_url=base, timeout=300) as http:
        for case in build():
            for route in ("/models", "/search", "/web/preview.png"):
                body = multipart(case.filename, case.content, case.fields)
                count("POST", route, content=body, headers=MULTIPART_HEADERS)
        good = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"
        for _, raw in bad_metadata():
            count(
                "POST",
                "/models",
                content=multipart("m.obj", good, {"metadata": raw}),
                headers=MULTIPART_HEADERS,
            )
        ids = [m["id"] for m in http.get("/models", params={"limit": 4}).json()["data"]]
        for model_id in ids:
            for size in (64, 128, 256, 512, 1024):
                count("GET", f"/models/{model_id}/thumbnail.png", params={"size": size})
    return codes


def rss_report(title: str, summary: dict) -> str:
    rows = [{"process": role, **row} for role, row in sorted(summary.items())]
    return table(rows, ["process", "processes", "peak_mb"], title=title)


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


def serve(data_dir: Path, workers: int, extra: dict[str, str] | None = None) -> tuple[subprocess.Popen, str]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = dict(
        os.environ,
        **FAST_ENV,
        SHAPEBAG_DATA_DIR=str(data_dir),
        SHAPEBAG_ADMIN_TOKEN="load-test-kkkkkkkkkkkkkkkkkkkkkk",
        SHAPEBAG_WORKERS=str(workers),
        **(extra or {}),
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
    ap.add_argument("--pid", type=int, default=None, help="with --url: the server's pid, for peak RSS")
    ap.add_argument("--no-hostile", action="store_true", help="skip the bad-input phase")
    args = ap.parse_args(argv)
    files = corpus_files()
    meshes = Meshes(files)
    proc = None
    rss: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="shapebag-load-") as tmp:
        base, pid, data_dir = args.url, args.pid, None
        if base is None:
            data_dir = Path(tmp) / "data"
            seed_data_dir(data_dir, files)
            # every client here connects from 127.0.0.1: one client to the server's per-client bound
            proc, base = serve(data_dir, args.workers, {"SHAPEBAG_CLIENT_REQUESTS": str(2 * args.clients),
                                                        "SHAPEBAG_CLIENT_UPLOADS": str(2 * args.clients)})
            pid = proc.pid
        try:
            if not args.no_hostile:
                with PeakRss(pid, data_dir) if pid else contextlib.nullcontext() as peaks:
                    codes = hostile(base)
                print(f"hostile phase: answers by status {dict(sorted(codes.items()))}")
                if peaks is not None:
                    rss["hostile"] = peaks.summary()
                    print(rss_report("peak RSS under the bad-input corpus", rss["hostile"]))
            with PeakRss(pid, data_dir) if pid else contextlib.nullcontext() as peaks:
                result = asyncio.run(drive(base, meshes, args.clients, args.seconds, args.upload_share))
            if peaks is not None:
                rss["load"] = peaks.summary()
        finally:
            if proc is not None:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(60)
    print(report(result))
    if "load" in rss:
        print(rss_report("peak RSS under load (the whole run, per process kind)", rss["load"]))
    result["peak_rss"] = rss
    write_json("load", result)
    return 0 if result["errors"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
