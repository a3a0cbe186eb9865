"""One hostile client beside one normal client, against a real server on 127.0.0.1 (issue 34).

    python -m benchmarks.hostile_load                    # 90 s, 300 flood uploads, a 160k-vertex model
    python -m benchmarks.hostile_load --seconds 30 --flood 40 --big 40000   # a quick look

A data directory is seeded here (SHREC'11 meshes and one large torus, ingested in this process with
the fast describe settings of benchmarks/load.py, a vocabulary fitted), then `shapebag serve` starts on
it with two embedded workers. Two clients connect from two loopback addresses, so the server tells them
apart as it would two hosts:
- the hostile one (127.0.0.3), in parallel: explains of the large stored model, thumbnails of two
  needles it uploads (a 1e6:1 cylinder, a strip of 20k slivers), and a flood of tiny valid uploads
  (`--flood`, each unique), several requests at a time, backing off as told on 429/503;
- the normal one (127.0.0.2): searches one after the other, and one upload, polled until described.
Printed: the normal client's search p50/p95/max and its answers by status (any 503 is a failure), its
upload's time to `ready`, the hostile client's answers by status, and the peak RSS of the API process
and its children. Goals: p95 <= 2 s, no 503 for the normal client, its upload ready within 30 s, the
API process under 1 GB. Bounded: a fixed duration, a fixed flood, a 120 s client timeout; exit 1 when a
goal is missed. Writes results/hostile_load.json.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import sqlite3
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np
import trimesh

from benchmarks.common import table, write_json
from benchmarks.load import FAST_ENV, Meshes, PeakRss, corpus_files, obj_bytes, seed_data_dir, serve

NORMAL, HOSTILE = "127.0.0.2", "127.0.0.3"
GOALS = {"search_p95_s": 2.0, "upload_ready_s": 30.0, "api_peak_mb": 1024.0}


def big_torus(vertices: int) -> bytes:
    """A torus of about `vertices` vertices, as binary PLY (the large stored model)."""
    side = max(8, int(np.sqrt(vertices)))
    t = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=side, minor_sections=side)
    return t.export(file_type="ply")


def needles() -> list[tuple[str, bytes]]:
    """A 1e6:1 cylinder and a needle of 20k slivers (a strip one triangle wide, 1e-6 thick)."""
    cyl = trimesh.creation.cylinder(radius=1e-6, height=1.0, sections=24)
    n = 10_000
    x = np.linspace(0.0, 1.0, n + 1)
    v = np.concatenate([np.stack([x, 0 * x, 0 * x], 1), np.stack([x, 0 * x + 1e-6, 0 * x + 1e-6], 1)])
    i = np.arange(n)
    f = np.concatenate([np.stack([i, i + 1, n + 1 + i], 1), np.stack([i + 1, n + 2 + i, n + 1 + i], 1)])
    return [("needle.obj", obj_bytes(cyl.vertices, cyl.faces)), ("slivers.obj", obj_bytes(v, f))]


def tiny(k: int) -> bytes:
    """A small valid mesh, unique per k (an icosphere of 42 vertices, nudged)."""
    s = trimesh.creation.icosphere(subdivisions=1)
    rng = np.random.default_rng(k)
    return obj_bytes(s.vertices + rng.normal(scale=0.01, size=s.vertices.shape), s.faces)


def client(address: str, base: str) -> httpx.AsyncClient:
    transport = httpx.AsyncHTTPTransport(local_address=address, retries=0)
    return httpx.AsyncClient(base_url=base, transport=transport, timeout=120)


class Tally:
    def __init__(self) -> None:
        self.codes: dict[str, dict[str, int]] = {}

    def add(self, kind: str, code: int | str) -> None:
        row = self.codes.setdefault(kind, {})
        row[str(code)] = row.get(str(code), 0) + 1


async def request(http: httpx.AsyncClient, tally: Tally, kind: str, method: str, url: str, **kw):
    """One request; on 429/503 waits as told (Retry-After) and returns None."""
    try:
        r = await http.request(method, url, **kw)
    except httpx.HTTPError as exc:
        tally.add(kind, type(exc).__name__)
        await asyncio.sleep(1.0)
        return None
    tally.add(kind, r.status_code)
    if r.status_code in (429, 503):
        await asyncio.sleep(float(r.headers.get("retry-after", "1")))
        return None
    return r


async def hostile(base: str, big_id: int, other_id: int, flood: int, stop: float, tally: Tally) -> None:
    async with client(HOSTILE, base) as http:
        needle_ids = []
        for name, data in needles():
            r = await request(http, tally, "upload", "POST", "/models", files={"file": (name, data)})
            if r is not None and r.status_code in (200, 202):
                needle_ids.append(r.json()["model_id"])
        sent = iter(range(flood))

        async def explains() -> None:
            while time.monotonic() < stop:
                params = {"against": other_id} if time.monotonic() % 2 < 1 else {}
                await request(http, tally, "explain", "GET", f"/models/{big_id}/explain", params=params)

        async def thumbnails() -> None:
            sizes = (128, 256, 512)
            k = 0
            while time.monotonic() < stop and needle_ids:
                url = f"/models/{needle_ids[k % len(needle_ids)]}/thumbnail.png"
                await request(http, tally, "thumbnail", "GET", url, params={"size": sizes[k % 3]})
                k += 1

        async def uploads() -> None:
            for k in sent:
                if time.monotonic() >= stop:
                    return
                await request(http, tally, "upload", "POST", "/models", files={"file": ("t.obj", tiny(k))})

        await asyncio.gather(
            *[explains() for _ in range(3)], *[thumbnails() for _ in range(2)], *[uploads() for _ in range(8)]
        )


def queued_jobs(data_dir: Path) -> int:
    conn = sqlite3.connect(f"file:{data_dir / 'shapebag.db'}?mode=ro", uri=True, timeout=5)
    try:
        return int(conn.execute("SELECT COUNT(*) FROM jobs WHERE state = 'queued'").fetchone()[0])
    finally:
        conn.close()


async def normal(base: str, meshes: Meshes, stop: float, tally: Tally, out: dict, data_dir: Path) -> None:
    latencies: list[float] = []
    timeline: list[tuple[float, float, int]] = []  # (seconds since start, latency, status)
    t0 = time.monotonic()
    async with client(NORMAL, base) as http:

        async def searches() -> None:
            while time.monotonic() < stop:
                name, data = meshes.query()
                t = time.perf_counter()
                r = await request(http, tally, "search", "POST", "/search", files={"file": (name, data)})
                took = time.perf_counter() - t
                if r is not None:
                    latencies.append(took)
                timeline.append(
                    (round(time.monotonic() - t0 - took, 2), round(took, 3), r.status_code if r else 0)
                )
                await asyncio.sleep(0.2)

        async def one_upload() -> None:
            await asyncio.sleep(10.0)  # the flood is under way
            out["queued_before_upload"] = await asyncio.to_thread(queued_jobs, data_dir)
            name, data = meshes.upload()
            t = time.perf_counter()
            r = await request(http, tally, "upload", "POST", "/models", files={"file": (name, data)})
            if r is None or r.status_code not in (200, 202):
                out["upload_error"] = None if r is None else f"{r.status_code} {r.text[:200]}"
                return
            model_id = r.json()["model_id"]
            while time.perf_counter() - t < 120:
                status = (await http.get(f"/models/{model_id}")).json()["status"]
                if status != "queued":
                    out["upload_status"] = status
                    out["upload_ready_s"] = time.perf_counter() - t
                    return
                await asyncio.sleep(0.25)

        await asyncio.gather(searches(), one_upload())
    out["search_latencies"] = latencies
    out["search_timeline"] = timeline


def summary(out: dict, normal: Tally, hostile: Tally, peaks: dict) -> dict:
    lat = np.asarray(out.get("search_latencies") or [np.nan])
    api_mb = peaks.get("api", {}).get("peak_mb", float("nan"))
    result = {
        "searches": int(np.isfinite(lat).sum()),
        "search_p50_s": float(np.percentile(lat, 50)),
        "search_p95_s": float(np.percentile(lat, 95)),
        "search_max_s": float(np.max(lat)),
        "normal_503": sum(row.get("503", 0) for row in normal.codes.values()),
        "upload_ready_s": out.get("upload_ready_s", float("inf")),
        "upload_status": out.get("upload_status", out.get("upload_error", "never described")),
        "queued_before_upload": out.get("queued_before_upload"),
        "api_peak_mb": api_mb,
        "normal_codes": normal.codes,
        "hostile_codes": hostile.codes,
        "peak_rss": peaks,
        "search_timeline": out.get("search_timeline", []),
    }
    result["goals_met"] = {
        "search p95 <= 2 s": result["search_p95_s"] <= GOALS["search_p95_s"],
        "no 503 for the normal client": result["normal_503"] == 0,
        "upload ready within 30 s": result["upload_ready_s"] <= GOALS["upload_ready_s"]
        and result["upload_status"] == "ready",
        "API under 1 GB": api_mb < GOALS["api_peak_mb"],
    }
    return result


def warm_up(base: str, meshes: Meshes, limit_s: float = 180.0) -> float:
    """Seconds until a search answers within 2 s: the pool's processes have started (cold processes
    on a loaded machine took 25 s, a cost of startup, not of the load)."""
    t = time.monotonic()
    with httpx.Client(base_url=base, timeout=120) as http:
        while time.monotonic() - t < limit_s:
            name, data = meshes.query()
            s = time.monotonic()
            if (
                http.post("/search", files={"file": (name, data)}).status_code == 200
                and time.monotonic() - s < 2
            ):
                break
    time.sleep(2.0)
    return time.monotonic() - t


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=90.0, help="how long both clients run")
    ap.add_argument("--flood", type=int, default=300, help="tiny uploads the hostile client sends at most")
    ap.add_argument("--big", type=int, default=160_000, help="vertices of the large stored model")
    ap.add_argument("--workers", type=int, default=2, help="embedded ingestion workers")
    args = ap.parse_args(argv)
    files = corpus_files()
    meshes = Meshes(files)
    with tempfile.TemporaryDirectory(prefix="shapebag-hostile-") as tmp:
        data_dir = Path(tmp) / "data"
        big = Path(tmp) / "big-torus.ply"
        big.write_bytes(big_torus(args.big))
        t = time.perf_counter()
        seed_data_dir(data_dir, [*files, big])
        took = time.perf_counter() - t
        print(f"seeded {len(files) + 1} models (one of ~{args.big:,} vertices) in {took:.0f} s")
        proc, base = serve(data_dir, args.workers)
        try:
            with httpx.Client(base_url=base, timeout=60) as http:
                rows = http.get("/models", params={"limit": 100}).json()["data"]
            big_id = next(m["id"] for m in rows if m["name"] == "big-torus")
            other_id = next(m["id"] for m in rows if m["id"] != big_id and m["status"] == "ready")
            warm = warm_up(base, meshes)
            print(f"pool warm after {warm:.0f} s (a search answered within 2 s)")
            normal_tally, hostile_tally, out = Tally(), Tally(), {}

            async def both() -> None:
                stop = time.monotonic() + args.seconds
                await asyncio.gather(
                    hostile(base, big_id, other_id, args.flood, stop, hostile_tally),
                    normal(base, meshes, stop, normal_tally, out, data_dir),
                )

            with PeakRss(proc.pid, data_dir) as peaks:
                asyncio.run(both())
            result = summary(out, normal_tally, hostile_tally, peaks.summary())
        finally:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(60)
    print(report(result, args))
    write_json("hostile_load", {**result, "args": vars(args), "env": FAST_ENV})
    return 0 if all(result["goals_met"].values()) else 1


def report(r: dict, args: argparse.Namespace) -> str:
    head = (
        f"hostile load: {args.seconds:g} s, flood of {args.flood}, large model ~{args.big:,} vertices, "
        f"{args.workers} workers\n"
        f"normal client: {r['searches']} searches, p50 {r['search_p50_s']:.2f} s,"
        f" p95 {r['search_p95_s']:.2f} s, max {r['search_max_s']:.2f} s; 503s: {r['normal_503']};"
        f" its upload: {r['upload_status']} after {r['upload_ready_s']:.1f} s"
        f" ({r['queued_before_upload']} jobs of the flood queued when it was sent)\n"
        f"answers to the normal client: {r['normal_codes']}\n"
        f"answers to the hostile client: {r['hostile_codes']}\n"
    )
    rss = [{"process": k, **v} for k, v in sorted(r["peak_rss"].items())]
    goals = "".join(f"  {'met   ' if ok else 'MISSED'} {goal}\n" for goal, ok in r["goals_met"].items())
    return head + table(rss, ["process", "processes", "peak_mb"], title="peak RSS") + "goals:\n" + goals


if __name__ == "__main__":
    sys.exit(main())
