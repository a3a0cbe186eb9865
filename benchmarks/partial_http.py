"""The time of a piece through HTTP: a real server over the 600 SHREC'11 models, pieces POSTed to /search.

    python -m benchmarks.partial_http SRC PIECES [--pieces 30] [--fill 0] [--cache-dir .cache/describe]
           [--data-dir DIR | --from-cache [--in-process [--budgets COARSE,SCORE]]]

Starts the service (benchmarks.service.start_server: uvicorn, 2 embedded workers, the shipped
vocabulary) on a temporary data directory, ingests every model of the labelled folder SRC over HTTP
(POST /models), then POSTs `--pieces` pieces of the folder PIECES (one a class, the first of each class
outside the picking split, as benchmarks.partial_served samples them) and as many whole models to
POST /search (k = 10, partial detection automatic), one at a time, and prints per kind the client's wall
time (p50 / p95 / max) and the server's split (describe, encode, search, partial). With --cache-dir
holding the pieces' and models' descriptions (benchmarks.partial_served fills it), it also checks that
each piece's 10 hits over HTTP are the ones benchmarks.partial_served ranks first. `--fill N` then adds
synthetic ready models with vectors (no description: they have no local signature) until the index
holds N, and times the pieces again: what the global search and the hit records cost at that size (their
partial stage still scores only the real models: benchmarks.partial_scale times a piece at 100k models
with signatures). `--data-dir` reuses the data directory of an earlier run (its ingest jobs resume; no
upload). `--from-cache` skips the HTTP ingest (over 30 minutes on the loaded shared cores): the models
are stored through the service's storage code from the --cache-dir descriptions (what ingestion would
store: the same describe; benchmarks.partial_scale.store_real), then the server starts on them.
Each answer says how much of the partial matching was done (the response's `partial`: models the coarse
pass read, candidates scored, whether a deadline cut either); the check against partial_served lists
the pieces whose 10 hits differ, and whether a deadline cut each. `--in-process` serves the FastAPI app
in this process (TestClient: httpx over ASGI, the lifespan and the query pool as uvicorn runs them), and
`--budgets` then replaces the two deadlines: a slower host's answer, on this one.
"""

from __future__ import annotations

import argparse
import contextlib
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from app.datasets.folder import LabelledFile, read_labelled_folder
from benchmarks.common import p50_p95
from benchmarks.partial_served import sample
from benchmarks.partial_spectra import _folder
from benchmarks.service import fill_index, free_port, ingest, start_server, stop_server, wait_until


def _post(client: httpx.Client, path: Path) -> tuple[float, dict[str, Any]]:
    t = time.perf_counter()
    r = client.post("/search", files={"file": (path.name, path.read_bytes())}, data={"k": "10"})
    r.raise_for_status()
    return time.perf_counter() - t, r.json()


def _summary(name: str, walls: list[float], bodies: list[dict[str, Any]]) -> dict[str, Any]:
    w = np.array(walls)
    split = {key: float(np.median([b.get("seconds", {}).get(key, np.nan) for b in bodies]))
             for key in ("describe", "encode", "search", "partial", "partial.coarse", "partial.score",
                         "partial.fit")}
    p50, p95 = p50_p95(walls)
    out = {"kind": name, "queries": len(w), "p50_s": p50, "p95_s": p95, "max_s": float(w.max()),
           "server_p50_s": split,
           "partial_hits": int(sum(bool(b["data"]) and bool(b["data"][0].get("partial")) for b in bodies))}
    work = [b["partial"] for b in bodies if b.get("partial")]
    out["coarse_cut"] = sum(w["coarse_cut"] for w in work)
    out["score_cut"] = sum(w["score_cut"] for w in work)
    out["fit_cut"] = sum(w.get("fit_cut", False) for w in work)
    print(f"  {name:6s} n {len(w):3d}  wall p50 {out['p50_s']:.3f} s  p95 {out['p95_s']:.3f} s  max "
          f"{out['max_s']:.3f} s;  server p50: " + ", ".join(f"{k} {v:.3f}" for k, v in split.items())
          + f";  answered as pieces {out['partial_hits']};  coarse pass cut {out['coarse_cut']}, scoring cut "
          f"{out['score_cut']}, fits cut {out['fit_cut']} (of {len(work)} reporting)")
    if work:
        read, scored = np.median([x["coarse_read"] for x in work]), np.median([x["scored"] for x in work])
        print(f"         coarse read p50 {read:.0f} of {max(x['coarse_of'] for x in work)}; scored p50 "
              f"{scored:.0f} of {np.median([x['scored_of'] for x in work]):.0f}; fitted p50 "
              f"{np.median([x.get('fitted', 0) for x in work]):.0f} of "
              f"{np.median([x.get('fitted_of', 0) for x in work]):.0f}")
    return out


def _agreement(pieces: list[LabelledFile], bodies: list[dict[str, Any]], src: Path,
               cache_dir: Path) -> None:
    """How many pieces' 10 hits over HTTP are benchmarks.partial_served's first 10, in order."""
    from app.core.vocabulary import Vocabulary
    from benchmarks.partial_rerank import VOCABULARY
    from benchmarks.partial_served import Served, described

    rows = read_labelled_folder(src)
    descs = described(rows, cache_dir, 1, src.name)
    vocab = Vocabulary.load(VOCABULARY)
    served = Served(np.stack([vocab.encode(d) for d in descs]).astype(np.float64), [d.local for d in descs])
    names = [r.path.stem for r in rows]
    same, first = 0, 0
    table: dict[tuple[bool, bool], int] = {}
    for piece, d, body in zip(pieces, described(pieces, cache_dir, 1, "pieces"), bodies, strict=True):
        ranked, _ = served.rank(d, served.global_order(vocab.encode(d).astype(np.float64)))
        offline = [names[j] for j in ranked[:10]]
        http = [h["name"] for h in body["data"]]
        same += offline == http
        first += offline[:1] == http[:1]
        work = body.get("partial") or {}
        cut = bool(work.get("coarse_cut") or work.get("score_cut") or work.get("fit_cut"))
        table[(offline == http, cut)] = table.get((offline == http, cut), 0) + 1
        if offline != http or cut:
            moved = sum(a != b for a, b in zip(offline, http, strict=False))
            verdict = "same" if offline == http else f"differs ({moved} ranks)"
            print(f"    {piece.path.stem}: top 10 {verdict}, "
                  f"first {'same' if offline[:1] == http[:1] else 'differs'}; coarse read "
                  f"{work.get('coarse_read')}/{work.get('coarse_of')}, scored {work.get('scored')}/"
                  f"{work.get('scored_of')}")
    print(f"  HTTP hits equal to benchmarks.partial_served's: all 10 for {same}/{len(bodies)} pieces, "
          f"the first for {first}/{len(bodies)}")
    print("  top 10 differs / same, against a deadline cut / none: "
          f"differs+cut {table.get((False, True), 0)}, differs+none {table.get((False, False), 0)}, "
          f"same+cut {table.get((True, True), 0)}, same+none {table.get((True, False), 0)}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src")
    p.add_argument("pieces")
    p.add_argument("--pieces", dest="count", type=int, default=30)
    p.add_argument("--fill", type=int, default=0)
    p.add_argument("--cache-dir", type=Path, default=None)
    p.add_argument("--data-dir", type=Path, default=None,
                   help="a data directory a run of this benchmark ingested SRC into (resumes its jobs)")
    p.add_argument("--from-cache", action="store_true",
                   help="store SRC's models from --cache-dir's descriptions instead of ingesting over HTTP")
    p.add_argument("--in-process", action="store_true",
                   help="the FastAPI app in this process (httpx through TestClient) instead of uvicorn;"
                        " with --from-cache")
    p.add_argument("--budgets", default=None, metavar="COARSE,SCORE",
                   help="--in-process: the coarse pass's and the scoring's deadlines in seconds (a slower"
                        " host's answer on this one)")
    a = p.parse_args(argv)
    src, qdir = _folder(a.src), _folder(a.pieces)
    rows = read_labelled_folder(src)
    qrows = read_labelled_folder(qdir)
    pieces = [qrows[i] for i in sample(qrows, 1, "held")][: a.count]
    wholes = [rows[i] for i in sample(rows, 1, "held")][: a.count]
    tmp = Path(tempfile.mkdtemp(prefix="shapebag-partial-http-"))
    data = a.data_dir or tmp / "data"
    if a.from_cache:
        if a.cache_dir is None or a.data_dir is not None:
            raise SystemExit("--from-cache needs --cache-dir, and a fresh data directory")
        from benchmarks.partial_scale import open_service, store_real
        from benchmarks.partial_served import described

        t = time.perf_counter()
        store_real(open_service(data), rows, described(rows, a.cache_dir, 1, src.name))
        print(f"stored {len(rows)} models from the description cache in {time.perf_counter() - t:.0f} s")
    elif a.in_process:
        raise SystemExit("--in-process needs --from-cache")
    with contextlib.ExitStack() as stack:
        if a.in_process:
            client = stack.enter_context(_in_process(data, a.budgets))
        else:
            client = stack.enter_context(_server(data, tmp, rows, ingest_first=a.data_dir is None
                                                 and not a.from_cache))
        _post(client, pieces[0].path)  # warm: the first search loads the index and the pool
        for size in ([len(rows)] + ([a.fill] if a.fill > len(rows) else [])):
            if size > len(rows):
                fill_index(data, size)
                wait_until(lambda s=size: client.get("/readyz").json()["checks"]["indexed_models"] >= s,
                           600, f"{size} indexed models", every_s=2)
            print(f"{size} models indexed; POST /search k=10, one at a time:")
            piece = [_post(client, r.path) for r in pieces]
            whole = [_post(client, r.path) for r in wholes]
            _summary("piece", [w for w, _ in piece], [b for _, b in piece])
            _summary("whole", [w for w, _ in whole], [b for _, b in whole])
            if a.cache_dir is not None and size == len(rows):
                _agreement(pieces, [b for _, b in piece], src, a.cache_dir)
    return 0


@contextlib.contextmanager
def _server(data: Path, tmp: Path, rows: list[LabelledFile], ingest_first: bool) -> Iterator[httpx.Client]:
    """A uvicorn server on `data` (benchmarks.service.start_server), SRC ingested over HTTP first when
    asked; a client of it once every model is indexed."""
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    proc = start_server(data, port, "faiss", tmp / "server.log")
    try:
        if ingest_first:
            ing = ingest(base, [(str(r.path), r.label) for r in rows])
            print(f"ingested {ing['ready']}/{ing['meshes']} models over HTTP in {ing['wall_s']:.0f} s "
                  f"(2 embedded workers); server log {tmp / 'server.log'}")
        wait_until(lambda: httpx.get(f"{base}/readyz", timeout=10).status_code == 200, 300, "the index")
        wait_until(lambda: httpx.get(f"{base}/readyz", timeout=10).json()["checks"]["indexed_models"]
                   >= len(rows), 3000, f"{len(rows)} indexed models (the ingest jobs left)", every_s=5)
        with httpx.Client(base_url=base, timeout=120) as client:
            yield client
    finally:
        stop_server(proc)


@contextlib.contextmanager
def _in_process(data: Path, budgets: str | None) -> Iterator[httpx.Client]:
    """The app of `data` in this process (its lifespan run: the index loaded, the query pool started),
    the partial matching's deadlines replaced when `budgets` says so."""
    from unittest import mock

    from fastapi.testclient import TestClient

    from app.config import Settings
    from app.main import create_app
    from app.services import partial as partial_mod

    patches = {}
    if budgets:
        coarse, score = (float(x) for x in budgets.split(","))
        patches = {"COARSE_BUDGET_S": coarse, "SCORE_BUDGET_S": score}
        print(f"deadlines: coarse pass {coarse} s, scoring {score} s (served: "
              f"{partial_mod.COARSE_BUDGET_S} s, {partial_mod.SCORE_BUDGET_S} s)")
    settings = Settings(data_dir=data, dev_mode=True, workers=0, search_processes=2, client_requests=64,
                        search_queue=64)
    with mock.patch.multiple(partial_mod, **patches) if patches else contextlib.nullcontext(), \
            TestClient(create_app(settings)) as client:
        yield client

if __name__ == "__main__":
    raise SystemExit(main())
