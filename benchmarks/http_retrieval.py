"""Retrieval quality through the HTTP service, as a user meets it: the shipped vocabulary, no fitting.

A real server (uvicorn, 2 embedded workers) on a loopback port over an empty temp data dir; every mesh
of a labelled folder is uploaded with POST /models (label = its class), and once all are ready every
model asks GET /models/{id}/similar?k=100 (the service's largest k). The rankings are scored with
app.core.metrics (NN FT ST E DCG mAP, as the PSB/SHREC tools define them).

The service answers at most 100 hits, so each ranking is completed with the models it left out,
relevant ones last: the scores are a lower bound, exact whenever every relevant model is in the top 100
(the "beyond 100" column counts those that were not).

    python -m benchmarks.http_retrieval                                   # SHREC'11, shipped vocabulary
    python -m benchmarks.http_retrieval DIR --env SHAPEBAG_ENCODE__FUSION=false
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from app.core import metrics
from app.datasets import locate
from benchmarks.common import table, write_json
from benchmarks.service import free_port, start_server, stop_server

DEFAULT_DIR = locate.dataset_dir("shrec11-simplified")  # SHAPEBAG_DATASETS/shrec11-simplified
MAX_K = 100


def read_labels(directory: Path) -> list[tuple[Path, str]]:
    with open(directory / "labels.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh)]
    return [(directory / r["file"], r["class"]) for r in rows]


def upload_all(client: httpx.Client, items: list[tuple[Path, str]]) -> dict[int, str]:
    """POST /models for each file -> {model id: class}."""
    ids: dict[int, str] = {}
    for path, label in items:
        reply = client.post(
            "/models", files={"file": (path.name, path.read_bytes())},
            data={"name": f"{label}/{path.stem}", "label": label},
        )
        reply.raise_for_status()
        ids.setdefault(int(reply.json()["model_id"]), label)  # identical bytes: one model
    return ids


def wait_ready(client: httpx.Client, expected: int, timeout_s: float) -> float:
    start = time.monotonic()
    while time.monotonic() - start < timeout_s:
        queued = client.get("/models", params={"status": "queued", "limit": 1}).json()["count"]
        failed = client.get("/models", params={"status": "failed", "limit": 1}).json()["count"]
        if failed:
            raise RuntimeError(f"{failed} uploads failed to describe")
        if queued == 0 and client.get("/models", params={"limit": 1}).json()["count"] == expected:
            return time.monotonic() - start
        time.sleep(1.0)
    raise RuntimeError(f"not every model was ready after {timeout_s} s")


def score(client: httpx.Client, ids: dict[int, str]) -> tuple[dict[str, float], int]:
    """Every model's ranking through /similar -> mean scores and the relevant models beyond the top 100."""
    order = list(ids)
    index = {mid: i for i, mid in enumerate(order)}
    labels = np.array([ids[m] for m in order])
    per_query: list[dict[str, float]] = []
    beyond = 0
    for mid in order:
        deadline = time.monotonic() + 60
        while True:  # the live index follows the database by polling: a just-ready model may lag
            reply = client.get(f"/models/{mid}/similar", params={"k": MAX_K})
            if reply.status_code != 503 or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        reply.raise_for_status()
        ranked = [index[h["model_id"]] for h in reply.json()["data"]]
        rest = [i for i in range(len(order)) if i != index[mid] and i not in set(ranked)]
        rest.sort(key=lambda i: labels[i] == ids[mid])  # worst case: the left-out relevant ones last
        beyond += sum(labels[i] == ids[mid] for i in rest)
        per_query.append(metrics.ranked_scores(np.array(ranked + rest), labels, ids[mid]))
    means = {name: float(np.mean([q[name] for q in per_query])) for name in per_query[0]}
    return means, beyond


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("directory", nargs="?", type=Path, default=DEFAULT_DIR, help="folder with labels.csv")
    ap.add_argument("--env", action="append", default=[], metavar="NAME=VALUE",
                    help="extra server setting, e.g. SHAPEBAG_ENCODE__FUSION=false (repeatable)")
    ap.add_argument("--timeout", type=float, default=3600, help="seconds to wait for ingestion")
    args = ap.parse_args()
    if not (args.directory / "labels.csv").is_file():
        ap.exit(2, f"{locate.missing_reason('shrec11-simplified') or f'no labels.csv in {args.directory}'}\n")
    items = read_labels(args.directory)
    for pair in args.env:
        name, _, value = pair.partition("=")
        os.environ[name] = value
    with tempfile.TemporaryDirectory(prefix="shapebag-http-") as tmp:
        port = free_port()
        proc = start_server(Path(tmp) / "data", port, "faiss", Path(tmp) / "server.log")
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=120) as client:
                vocab = client.get("/admin/vocabulary", headers={"X-Admin-Token": "change-me"}).json()
                t0 = time.monotonic()
                ids = upload_all(client, items)
                wait_ready(client, len(ids), args.timeout)
                ingest_s = time.monotonic() - t0  # uploads and descriptions, counted once
                time.sleep(2.0)  # one more poll of the live index
                scores, beyond = score(client, ids)
        finally:
            stop_server(proc)
    row = {k: round(v, 4) for k, v in scores.items()}
    print(f"{args.directory}: {len(items)} meshes over HTTP, ingested in {ingest_s:.0f} s; "
          f"vocabulary {vocab.get('id')} ({vocab.get('metadata', {}).get('source', '?')}), "
          f"fusion {vocab.get('metadata', {}).get('fusion')}")
    print(table([dict(row, beyond_100=beyond, settings=" ".join(args.env) or "defaults")]))
    write_json("http_retrieval", {"directory": str(args.directory), "scores": scores, "beyond_100": beyond,
                                  "ingest_s": ingest_s, "env": args.env, "vocabulary": vocab})


if __name__ == "__main__":
    main()
