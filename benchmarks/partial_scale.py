"""A piece's search at 600, 10k and 100k models: in-process, through the service's storage, index and
search code, per stage, with what the deadlines cut.

    python -m benchmarks.partial_scale [--sizes 600,10000,100000] [--pieces 30] [--wholes 30]
           [--src shrec11-simplified] [--queries var/p6085] [--cache-dir .cache/describe]
           [--work var/scale] [--json var/scale.json]

For each size N, a fresh data directory is filled through the service's own storage code (the model
rows, their vectors under the shipped vocabulary, their descriptions in the blob store) and opened as
the server opens it (open_context, the shipped vocabulary registered, LiveIndex over the database: the
FAISS flat L1 index):
- the 600 real SHREC'11 models of SRC, described by describe() through the evaluation cache (the
  ingestion's describe: canonical_with_rim + the same pipeline), their full descriptions stored;
- N - 600 synthetic models, each made from a real one, a: its global vector (1 - w)·v_a + w·v_b
  (b another real model, w uniform in [0, 0.3]) with each entry times exp(N(0, 0.1²)), and a's local
  signature with N(0, 0.03²) added to every slope (the match tolerance is 2·10⁻³ in mean squared slope:
  a copy still matches its source closely, and the coarse pass and the scoring do a real match each)
  and a's surface (so a copy is screened and fitted as a real model is, and a piece lies on copies of
  its source).
  Only what a search reads of a description is stored for them (the local signature's members and
  the input noise, as ShapeDescription.save writes them, compressed): the HKS table, weights, keypoints
  and eigenvalues (what a vocabulary rebuild, the explain view and the variant check read) are left out,
  and so are their meshes, thumbnails and views. They carry a's label.
Then `--pieces` one-cut pieces of QUERIES (one a class, outside the picking split, as
benchmarks.partial_http samples them; their descriptions from the same cache) go through
app.services.search.search_description (k = 10, partial detection automatic), one at a time, after one
warm-up query, and `--wholes` whole models of SRC as well. Printed per size: p50 / p95 of each stage
(global search, hit records, coarse pass, full scoring, vote, peers, fits, regions) and of the whole
call, the work the deadlines left (models the coarse pass read of those it was to read, candidates
scored of those chosen, fits made of those chosen, how often each was cut), the same pieces again with
the three deadlines lifted (their stage times, and whether the served top 10 and first hit are the
lifted ones), what one model of the coarse pass costs (reading its signature without the LRU, and its
coarse match; 5 pieces), the index and descriptions on disk, the index in memory, and the ratios
against the first size, measured in the same process. The query describe (about 0.4 s through HTTP,
docs/partial.md) is not part of these times.
The LRU of local signatures starts empty at each size; the descriptions written a moment before are
in the OS page cache (a cold read here parses an npz from memory, not from disk).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

from app.core.partial import LocalSignature
from app.core.pipeline import DESCRIPTION_FORMAT, DescribeParams, ShapeDescription, local_members
from app.datasets.folder import LabelledFile, read_labelled_folder
from app.services import partial as partial_mod
from app.services import search as search_mod
from app.services.context import ServiceContext
from benchmarks.common import p50_p95
from benchmarks.partial_served import described, sample
from benchmarks.partial_spectra import _folder

STAGES = ("search", "partial.records", "partial.coarse", "partial.score", "partial.vote", "partial.peers",
          "partial.fit", "partial.regions")
SLOPE_JITTER = 0.03  # per slope (and on the level), added to a synthetic model's copy of a real signature
VECTOR_JITTER = 0.1  # log-normal, per entry of a synthetic model's global vector
MAX_MIX = 0.3  # a synthetic vector's weight of a second real model
BATCH = 5000  # synthetic models per transaction


def open_service(data_dir: Path) -> ServiceContext:
    from app.config import Settings
    from app.services import vocabularies
    from app.services.context import open_context

    ctx = open_context(Settings(data_dir=data_dir, dev_mode=True))
    vocabularies.ensure_default(ctx)  # as the server's lifespan does: the shipped vocabulary
    if ctx.settings.describe.params() != DescribeParams():
        raise SystemExit("the service's describe settings are not the evaluation cache's defaults")
    return ctx


def _encoder(ctx: ServiceContext) -> tuple[int, Any]:
    """(active vocabulary id, description -> (v,) float32 vector) as ingestion encodes."""
    from app.services.vocabularies import load_vocabulary, version_params
    from app.storage import vocabularies as vocab_repo

    with ctx.db.read() as conn:
        record = vocab_repo.active(conn)
    assert record is not None
    vocab = load_vocabulary(ctx, record)
    params = version_params(ctx, record, vocab)
    return record.id, lambda d: vocab.encode(d, params)


def _save_signature(path: Path, sig: LocalSignature, input_noise: float) -> None:
    """What load_local_and_noise reads of a description, in ShapeDescription.save's members."""
    with open(path, "wb") as fh:
        np.savez_compressed(fh, input_noise=np.float64(input_noise), format=np.int64(DESCRIPTION_FORMAT),
                            **local_members(sig))


def store_real(ctx: ServiceContext, rows: Sequence[LabelledFile],
               descs: Sequence[ShapeDescription]) -> list[int]:
    """The real models as ingestion leaves them (row, full description, vector, ready); their ids."""
    from app.storage import models as models_repo
    from app.storage import vocabularies as vocab_repo

    vid, encode = _encoder(ctx)
    ctx.blobs.description_path(0).parent.mkdir(parents=True, exist_ok=True)
    ids = []
    with ctx.db.write() as conn:
        for r, d in zip(rows, descs, strict=True):
            mid = models_repo.insert(conn, name=r.path.stem, label=r.label, metadata={},
                                     sha256=f"real-{r.path.stem}", file_type=r.path.suffix.lstrip("."),
                                     size_bytes=r.path.stat().st_size)
            d.save(ctx.blobs.description_path(mid))
            vocab_repo.put_vector(conn, mid, vid, encode(d))
            models_repo.set_ready(conn, mid, d.input_vertices)
            ids.append(mid)
    return ids


def store_synthetic(ctx: ServiceContext, rows: Sequence[LabelledFile], descs: Sequence[ShapeDescription],
                    count: int, seed: int = 0) -> None:
    """`count` synthetic models made from the real ones (the module's docstring says how)."""
    from app.storage import models as models_repo
    from app.storage import vocabularies as vocab_repo

    vid, encode = _encoder(ctx)
    real = np.stack([encode(d) for d in descs]).astype(np.float64)
    rng = np.random.default_rng(seed)
    ctx.blobs.description_path(0).parent.mkdir(parents=True, exist_ok=True)
    for start in range(0, count, BATCH):
        m = min(BATCH, count - start)
        a, b = rng.integers(0, len(descs), m), rng.integers(0, len(descs), m)
        w = rng.uniform(0.0, MAX_MIX, (m, 1))
        vectors = ((1 - w) * real[a] + w * real[b]) * np.exp(rng.normal(0.0, VECTOR_JITTER, real[a].shape))
        with ctx.db.write() as conn:
            for i in range(m):
                src = descs[a[i]]
                assert src.local is not None
                mid = models_repo.insert(conn, name=f"synthetic-{start + i}-of-{rows[a[i]].path.stem}",
                                         label=rows[a[i]].label, metadata={"synthetic": True},
                                         sha256=f"synthetic-{seed}-{start + i:08d}", file_type="ply",
                                         size_bytes=0)
                slopes = src.local.slopes + rng.normal(0.0, SLOPE_JITTER, src.local.slopes.shape)
                level = None if src.local.level is None else (
                    src.local.level + rng.normal(0.0, SLOPE_JITTER, src.local.level.shape)).astype(np.float32)
                # the source's surface too: a copy is screened and fitted as a real model is
                sig = LocalSignature(slopes=slopes.astype(np.float32), area=src.local.area,
                                     valid=src.local.valid, rim=src.local.rim, vertex=src.local.vertex,
                                     level=level, surface=src.local.surface)
                _save_signature(ctx.blobs.description_path(mid), sig, src.input_noise)
                vocab_repo.put_vector(conn, mid, vid, vectors[i].astype(np.float32))
                models_repo.set_ready(conn, mid, src.input_vertices)


def _bytes_under(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _queries(ctx: ServiceContext, live: Any, descs: Sequence[ShapeDescription],
             lifted: bool = False) -> list[dict[str, Any]]:
    """search_description of each description, one at a time: its stage seconds, work, top 10."""
    out = []
    budgets = ({"COARSE_BUDGET_S": float("inf"), "SCORE_BUDGET_S": float("inf"), "FIT_BUDGET_S": float("inf")}
               if lifted else {})
    with mock.patch.multiple(partial_mod, **budgets) if budgets else contextlib.nullcontext():
        for d in descs:
            t = time.perf_counter()
            result = search_mod.search_description(ctx, live, d, 10)
            wall = time.perf_counter() - t
            w = result.partial
            out.append({
                "wall": wall, "seconds": dict(result.seconds), "top": [h.model.id for h in result.hits],
                "labels": [h.model.label for h in result.hits],
                "work": None if w is None else {"coarse_read": w.coarse_read, "coarse_of": w.coarse_of,
                                                "scored": w.scored, "scored_of": w.scored_of,
                                                "coarse_cut": w.coarse_cut, "score_cut": w.score_cut,
                                                "fitted": w.fitted, "fitted_of": w.fitted_of,
                                                "fit_cut": w.fit_cut},
            })
    return out


def per_model_costs(ctx: ServiceContext, live: Any, pieces: Sequence[ShapeDescription]) -> dict[str, float]:
    """Median over `pieces` of the ms a model of the coarse pass costs: reading its signature from its
    description (load_local_and_noise, no LRU: what a miss costs) and its coarse match (match_many of
    the query's COARSE_POINTS head, in chunks of CHUNK), over the piece's COARSE_SCAN global nearest."""
    from app.core.partial_match import head, match_many
    from app.core.pipeline import LOCAL, load_local_and_noise

    read, match = [], []
    for d in pieces:
        assert d.local is not None
        _, vector = live.encode(d)
        _, ids, _ = live.search(vector, partial_mod.COARSE_SCAN)
        t = time.perf_counter()
        sigs = [load_local_and_noise(ctx.blobs.description_path(int(i)))[0] for i in ids]
        read.append(1e3 * (time.perf_counter() - t) / len(ids))
        query = head(d.local, partial_mod.COARSE_POINTS)
        t = time.perf_counter()
        for start in range(0, len(sigs), partial_mod.CHUNK):
            match_many(query, [s for s in sigs[start:start + partial_mod.CHUNK] if s is not None], LOCAL)
        match.append(1e3 * (time.perf_counter() - t) / len(ids))
    return {"read_ms": float(np.median(read)), "match_ms": float(np.median(match)), "models": len(ids)}


def _stages(runs: list[dict[str, Any]]) -> dict[str, tuple[float, float]]:
    out = {s: p50_p95([r["seconds"].get(s, 0.0) for r in runs]) for s in STAGES}
    out["call"] = p50_p95([r["wall"] for r in runs])
    return out


def measure(size: int, work_dir: Path, rows: Sequence[LabelledFile], descs: Sequence[ShapeDescription],
            pieces: Sequence[ShapeDescription], piece_labels: Sequence[str], wholes: Sequence[int],
            keep: bool) -> dict[str, Any]:
    from app.services.live_index import LiveIndex

    data_dir = work_dir / f"n{size}"
    if data_dir.exists():
        shutil.rmtree(data_dir)
    t = time.perf_counter()
    ctx = open_service(data_dir)
    store_real(ctx, rows, descs)
    store_synthetic(ctx, rows, descs, size - len(rows))
    build_s = time.perf_counter() - t
    rss0 = _rss_mb()
    t = time.perf_counter()
    live = LiveIndex(ctx)
    live.refresh()
    load_s = time.perf_counter() - t
    rss1 = _rss_mb()
    pair = live.require()
    live.save(force=True)
    index_file = ctx.index_path(pair.record.id)
    partial_mod._CACHE = partial_mod.LocalCache()  # the LRU starts empty at each size
    load0 = os.getloadavg()[0]
    search_mod.search_description(ctx, live, pieces[0], 10)  # warm-up (not timed)
    served = _queries(ctx, live, pieces)
    whole = _queries(ctx, live, [descs[i] for i in wholes])
    lifted = _queries(ctx, live, pieces, lifted=True)
    costs = per_model_costs(ctx, live, pieces[:5])
    load1 = os.getloadavg()[0]
    works = [r["work"] for r in served]
    pairs = list(zip(served, lifted, strict=True))
    desc_dir = ctx.blobs.description_path(0).parent
    real_bytes = [ctx.blobs.description_path(i).stat().st_size for i in range(1, len(rows) + 1)]
    synth_bytes = [ctx.blobs.description_path(i).stat().st_size
                   for i in range(len(rows) + 1, min(size, len(rows) + 2000) + 1)]
    out = {
        "size": size, "build_s": build_s, "index_load_s": load_s, "load_avg": [load0, load1],
        "index_file_bytes": index_file.stat().st_size,
        "index_memory_bytes": pair.index.count * (pair.index.dim * 4 + 8),
        "rss_index_mb": rss1 - rss0,
        "database_bytes": sum(p.stat().st_size for p in data_dir.glob("*.db*")),
        "descriptions_bytes": _bytes_under(desc_dir),
        "real_description_bytes": float(np.mean(real_bytes)),
        "synthetic_signature_bytes": float(np.mean(synth_bytes)) if synth_bytes else None,
        "piece": _stages(served), "whole": _stages(whole), "lifted": _stages(lifted), "per_model": costs,
        "coarse_read": [w["coarse_read"] for w in works], "coarse_of": [w["coarse_of"] for w in works],
        "scored": [w["scored"] for w in works], "scored_of": [w["scored_of"] for w in works],
        "coarse_cut": sum(w["coarse_cut"] for w in works), "score_cut": sum(w["score_cut"] for w in works),
        "fitted": [w["fitted"] for w in works], "fitted_of": [w["fitted_of"] for w in works],
        "fit_cut": sum(w["fit_cut"] for w in works),
        "whole_score_cut": sum(r["work"]["score_cut"] for r in whole if r["work"]),
        "same_top10_as_lifted": sum(a["top"] == b["top"] for a, b in pairs),
        "same_first_as_lifted": sum(a["top"][:1] == b["top"][:1] for a, b in pairs),
        "nn_served": _nn(served, piece_labels), "nn_lifted": _nn(lifted, piece_labels),
        "first_real_served": sum(0 < r["top"][0] <= len(rows) for r in served),
        "per_piece": [{"served": s["work"], "served_s": s["seconds"], "lifted_s": li["seconds"],
                       "same_top10": s["top"] == li["top"]} for s, li in pairs],
    }
    if not keep:
        shutil.rmtree(data_dir)
    _print(out)
    return out


def _nn(runs: list[dict[str, Any]], labels: Sequence[str]) -> float:
    return float(np.mean([r["labels"][:1] == [lab] for r, lab in zip(runs, labels, strict=True)]))


def _short(stage: str) -> str:
    return stage.replace("partial.", "")


def _print(r: dict[str, Any]) -> None:
    mb = 2**20
    print(f"\n{r['size']:,} models (built in {r['build_s']:.0f} s, index loaded in "
          f"{r['index_load_s']:.2f} s; load average {r['load_avg'][0]:.1f} -> {r['load_avg'][1]:.1f})")
    print(f"  disk: index {r['index_file_bytes'] / mb:.1f} MB, database {r['database_bytes'] / mb:.1f} MB, "
          f"descriptions {r['descriptions_bytes'] / mb:.0f} MB (real "
          f"{r['real_description_bytes'] / 1e3:.1f} kB each; synthetic signature-only "
          + (f"{r['synthetic_signature_bytes'] / 1e3:.1f} kB" if r["synthetic_signature_bytes"] else "-")
          + f");  memory: index {r['index_memory_bytes'] / mb:.1f} MB (RSS +{r['rss_index_mb']:.0f} MB)")
    for kind in ("piece", "whole", "lifted"):
        s = r[kind]
        print(f"  {kind:6s} p50/p95 ms: " + "  ".join(
            f"{_short(name)} {1e3 * s[name][0]:.1f}/{1e3 * s[name][1]:.1f}" for name in (*STAGES, "call")))
    print(f"  pieces: coarse read {int(np.median(r['coarse_read']))} (min {min(r['coarse_read'])}) of "
          f"{max(r['coarse_of'])}, cut {r['coarse_cut']}/{len(r['coarse_read'])};  scored "
          f"{int(np.median(r['scored']))} (min {min(r['scored'])}) of {int(np.median(r['scored_of']))}, cut "
          f"{r['score_cut']}/{len(r['scored'])};  fitted {int(np.median(r['fitted']))} "
          f"(min {min(r['fitted'])}) of {int(np.median(r['fitted_of']))}, "
          f"cut {r['fit_cut']}/{len(r['fitted'])};  "
          f"top 10 = lifted for {r['same_top10_as_lifted']}, first "
          f"{r['same_first_as_lifted']};  NN served {r['nn_served']:.3f} lifted {r['nn_lifted']:.3f} "
          f"(synthetic copies carry their source's label); first hit a real model {r['first_real_served']}; "
          f"whole queries' scoring cut {r['whole_score_cut']}")
    c = r["per_model"]
    print(f"  a model of the coarse pass (median of 5 pieces, over their {c['models']} global nearest): "
          f"reading its signature {c['read_ms']:.3f} ms (no LRU), its coarse match {c['match_ms']:.3f} ms")


def _ratios(results: list[dict[str, Any]]) -> None:
    base = results[0]
    print(f"\nratios of the p50s against {base['size']:,} models (same process):")
    for r in results[1:]:
        parts = []
        for name in (*STAGES, "call"):
            b = base["piece"][name][0]
            parts.append(f"{_short(name)} x{r['piece'][name][0] / b:.1f}" if b > 0 else f"{_short(name)} -")
        lifted = r["lifted"]["call"][0] / base["lifted"]["call"][0]
        whole = r["whole"]["call"][0] / base["whole"]["call"][0]
        print(f"  {r['size']:>7,}: piece " + ", ".join(parts)
              + f";  lifted call x{lifted:.1f};  whole call x{whole:.1f}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="600,10000,100000")
    p.add_argument("--pieces", type=int, default=30)
    p.add_argument("--wholes", type=int, default=30)
    p.add_argument("--src", default="shrec11-simplified")
    p.add_argument("--queries", default="var/p6085", help="pieces written by benchmarks.partial")
    p.add_argument("--cache-dir", type=Path, default=Path(".cache/describe"))
    p.add_argument("--work", type=Path, default=Path("var/scale"), help="scratch data directories")
    p.add_argument("--keep", action="store_true", help="keep each size's data directory")
    p.add_argument("--json", type=Path, default=None)
    a = p.parse_args(argv)
    sizes = [int(s) for s in a.sizes.split(",")]
    src, qdir = _folder(a.src), _folder(a.queries)
    rows = read_labelled_folder(src)
    if min(sizes) < len(rows):
        raise SystemExit(f"every size holds the {len(rows)} real models")
    descs = described(rows, a.cache_dir, 1, "models")
    qrows = read_labelled_folder(qdir)
    chosen = [qrows[i] for i in sample(qrows, 1, "held")][: a.pieces]
    pieces = described(chosen, a.cache_dir, 1, "pieces")
    wholes = sample(rows, 1, "held")[: a.wholes]
    print(f"{len(pieces)} pieces of {qdir.name}, {len(wholes)} whole models; sizes {sizes}; "
          f"deadlines: coarse {partial_mod.COARSE_BUDGET_S} s, scoring {partial_mod.SCORE_BUDGET_S} s, "
          f"fits {partial_mod.FIT_BUDGET_S} s; "
          f"coarse scan {partial_mod.COARSE_SCAN}, candidates {partial_mod.RERANK}")
    results = [measure(n, a.work, rows, descs, pieces, [r.label for r in chosen], wholes, a.keep)
               for n in sizes]
    if len(results) > 1:
        _ratios(results)
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(results, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
