"""Ingest cost of the variant step on the realworld corpus, through the service's own code.

    python -m benchmarks.variants_ingest [--limit 40] [--max-vertices 60000]

Every readable realworld mesh (in name order, up to --limit) is stored in a scratch data directory,
one after the other, as uploads arrive; for each, the ingest's numerical work (parse + describe +
view mesh, services.ingestion) is timed, then services.variants.detect (fingerprints, lookup among the
models stored before it, verification of the candidates, links written), twice on identical copies
of the collection: with the cache of prepared candidate meshes, and with a cache that keeps nothing
(every candidate read and prepared afresh, as before the cache). Prints the totals and the overhead.
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
from app.services import ingestion, variants
from app.services.context import ServiceContext, open_context
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
    ingest_s = variant_s = 0.0
    links = n = 0
    for path in files:
        data = path.read_bytes()
        try:
            model = ingestion.submit(ctx, data, path.name).model
            t = time.perf_counter()
            mesh = load_mesh(data, model.file_type, max_vertices=ctx.settings.max_vertices)
            ingestion.describe_and_view(mesh, params)
        except (InvalidMeshError, ValueError) as exc:
            print(f"skipped {path.name}: {exc}")
            continue
        ingest_s += time.perf_counter() - t
        found, seconds = variants.timed_detect(ctx, model.id, mesh)
        variant_s += seconds
        links += len(found)
        n += 1
    cache = variants.prepared_cache(ctx)
    return {"cache": "LRU" if cached else "none", "models": n, "parse+describe s": ingest_s,
            "variant step s": variant_s, "overhead": variant_s / ingest_s if ingest_s else float("nan"),
            "links": links, "cache hits": cache.hits, "cache misses": cache.misses}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--limit", type=int, default=40, help="meshes (default 40, in name order)")
    ap.add_argument("--max-vertices", type=int, default=60_000)
    args = ap.parse_args(argv)
    try:
        root = locate.require("realworld")
    except locate.DatasetMissing as exc:
        print(f"variants_ingest: {exc}")
        return 2
    files = corpus(root, args.limit, args.max_vertices)
    rows = []
    for cached in (True, False):
        with tempfile.TemporaryDirectory() as tmp:
            rows.append(run(files, open_context(Settings(data_dir=Path(tmp) / "data")), cached))
        print(rows[-1], flush=True)  # each run as it ends: a long one may be cut short
    title = f"ingest of {len(files)} realworld meshes, the variant step with and without the cache"
    print(table(rows, title=title))
    print(machine())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
