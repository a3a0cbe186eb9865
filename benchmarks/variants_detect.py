"""Variant detection: precision and recall per relation, confidence calibration, lookup and ingest cost.

    python -m benchmarks.variants_detect [--real 6] [--shrec 6] [--full] [--lookup-sizes 100000,1000000]
    python -m benchmarks.variants_detect --lookup-only --lookup-sizes 100000,1000000

Bases come from the realworld corpus and SHREC'11 (evenly spaced in name order, at most one per
SHREC'11 class; bases the detector relates to an earlier base are dropped and named). Each base gets
the variants of benchmarks/variants_detect_kinds.py; other members of a chosen SHREC'11 class are hard
negatives (must come out `similar`), and every base is looked for in print plates mixing it with two
other bases (`part_of`). Every query goes through the service's path: fingerprint, index lookup of
its whole and its objects, verification of at most --verify candidates. A true pair the lookup misses
counts as `similar`. `--full` takes every readable realworld mesh up to 60k vertices and 30 SHREC'11
classes, and all of trimesh's writers. The lookup is timed on synthetic fingerprints drawn from the
measured ones' mean and covariance (FAISS HNSW past 20k; building 1M takes minutes on a busy core).
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

from app.core.mesh import InvalidMeshError, Mesh, load_mesh
from app.core.variants import RELATIONS, Prepared, relate
from app.core.variants.collection import RADIUS, K, shortlist
from app.core.variants.gate import coarsening
from app.core.variants.index import FingerprintIndex
from app.core.variants.relate import verify
from app.datasets import locate
from benchmarks.common import machine, table
from benchmarks.variants_detect_kinds import plate_member, variants
from benchmarks.variants_tools import tool_variants

# the two samples the gate's bounds were derived from (docs/variants.md): --held-out leaves their bases out
DERIVED_FROM = (6, 12)


def _spread(items: list, n: int) -> list:
    return items if n >= len(items) else [items[int(i)] for i in np.linspace(0, len(items) - 1, n).round()]


def _held_out(items: list, n: int) -> list:
    """`n` evenly spread of the items that neither derivation sample picked."""
    seen = {id(x) for m in DERIVED_FROM for x in _spread(items, m)}
    return _spread([x for x in items if id(x) not in seen], n)


def pick_real(root: Path, n: int, max_vertices: int, held_out: bool = False) -> list[tuple[str, Mesh]]:
    with open(root / "STATS.csv") as fh:
        rows = sorted(csv.DictReader(fh), key=lambda r: r["file"])
    ok = [r for r in rows if r["loader_result"] == "ok" and r["merged_verts"].isdigit()
          and 20 <= int(r["merged_verts"]) <= max_vertices]
    out = []
    for r in ok:
        try:
            out.append((f"real/{r['file']}", load_mesh(root / r["file"])))
        except InvalidMeshError:
            continue
    return _held_out(out, n) if held_out else _spread(out, n)


def pick_shrec(root: Path, n: int, negatives: int,
               held_out: bool = False) -> tuple[list[tuple[str, Mesh]], dict[str, list]]:
    """One base per chosen class (its first member; held out: classes neither derivation sample chose,
    their last member, which also took no part in setting the one-sided thresholds) and
    `negatives` other members of its class."""
    by_class: dict[str, list[str]] = defaultdict(list)
    with open(root / "labels.csv") as fh:
        for r in csv.DictReader(fh):
            by_class[r["class"]].append(r["file"])
    classes = sorted(by_class)
    chosen = _held_out(classes, n) if held_out else _spread(classes, n)
    bases, negs = [], {}
    for c in chosen:
        files = sorted(by_class[c])
        base, others = files[0], files[1: 1 + negatives]
        if held_out:
            base, others = files[-1], files[-1 - negatives:-1]
        bases.append((f"shrec/{base}", load_mesh(root / base)))
        negs[f"shrec/{base}"] = [(f"shrec/{f}", load_mesh(root / f)) for f in others]
    return bases, negs


def distinct(bases: list[tuple[str, Mesh]]) -> tuple[list[tuple[str, Prepared]], list[str]]:
    """Drop a base the detector relates to an earlier one (the corpus has one model in two formats)."""
    kept: list[tuple[str, Prepared]] = []
    dropped = []
    for name, mesh in bases:
        p = Prepared(mesh)
        near = [(n, q) for n, q in kept if np.linalg.norm(p.fingerprint - q.fingerprint) <= RADIUS]
        hit = next(((n, r.relation) for n, q in near if (r := relate(p, q)).relation != "similar"), None)
        if hit:
            dropped.append(f"{name} ~ {hit[0]} ({hit[1]})")
        else:
            kept.append((name, p))
    return kept, dropped


class Run:
    """Queries against a stored set through the lookup; predictions per (query, stored) pair."""

    def __init__(self, stored: list[tuple[str, Prepared]]) -> None:
        self.stored = stored
        keys, vectors = [], []
        for i, (_, p) in enumerate(stored):
            for v in [p.fingerprint] + [q.fingerprint for q in p.parts if q is not p]:
                keys.append(i)
                vectors.append(v)
        self.index = FingerprintIndex()
        self.index.build(np.array(keys), np.array(vectors))
        self.pairs: list[dict] = []
        self.seconds: defaultdict[str, float] = defaultdict(float)

    def query(self, name: str, kind: str, q: Prepared, truth: dict[int, str]) -> None:
        t = time.perf_counter()
        vectors = np.array([q.fingerprint] + [p.fingerprint for p in q.parts if p is not q])
        self.seconds["prepare"] += time.perf_counter() - t
        t = time.perf_counter()
        found = shortlist(self.index, vectors)
        self.seconds["lookup"] += time.perf_counter() - t
        for i in set(found) | set(truth):
            expected = truth.get(i, "similar")
            if i in found:
                t = time.perf_counter()
                ev = relate(q, self.stored[i][1])
                self.seconds["verify"] += time.perf_counter() - t
                got, conf, ch, hd = ev.relation, ev.confidence, ev.chamfer, ev.hausdorff
                screened = ev.screened
            else:
                got, conf, ch, hd, screened = "similar", 1.0, float("nan"), float("nan"), False
            # a true pair ruled out without a fit: what the whole-surface fit would have said
            unscreened = verify(q, self.stored[i][1]).relation if screened and expected != "similar" else None
            # area / diagonal^2 against the stored one's: a decimation that lost thin parts shows here
            stored = self.stored[i][1]
            area = (q.mesh.area() / q.diagonal**2) / (stored.mesh.area() / stored.diagonal**2)
            rows = np.array([stored.fingerprint] + [o.fingerprint for o in stored.parts if o is not stored])
            self.pairs.append({"query": name, "kind": kind, "stored": self.stored[i][0], "truth": expected,
                               "area_ratio": area,
                               "fp_whole": float(np.linalg.norm(q.fingerprint - stored.fingerprint)),
                               "fp_near": float(np.linalg.norm(vectors[:, None] - rows[None], axis=2).min()),
                               "coarsening": coarsening(q, stored),
                               "got": got, "confidence": conf, "looked_up": i in found,
                               "chamfer": ch, "hausdorff": hd, "screened": screened,
                               "fit_without_gate": unscreened})


def mirror_truth(variant: Prepared, base: Prepared) -> str:
    """A mirror image the exact test fits by a proper motion (a mirror-symmetric base with a symmetric
    triangulation) is that motion: 'mirrored' otherwise."""
    ev = relate(variant, base)
    return ev.relation if ev.relation in ("identical", "moved") else "mirrored"


def scores(pairs: list[dict]) -> list[dict]:
    rows = []
    for rel in RELATIONS:
        truth = [p for p in pairs if p["truth"] == rel]
        said = [p for p in pairs if p["got"] == rel]
        hits = sum(p["got"] == rel for p in truth)
        rows.append({"relation": rel, "true pairs": len(truth), "said": len(said), "correct": hits,
                     "precision": hits / len(said) if said else float("nan"),
                     "recall": hits / len(truth) if truth else float("nan")})
    return rows


def kept_surface(pairs: list[dict], tolerance: float = 0.1) -> str:
    """Re-triangulated recall with and without the copies whose area (over the diagonal squared, so
    any scale) changed by more than `tolerance`: a decimation that dropped that much of the surface."""
    truth = [p for p in pairs if p["truth"] == "retriangulated"]
    kept = [p for p in truth if abs(p["area_ratio"] - 1.0) <= tolerance]
    hits = sum(p["got"] == "retriangulated" for p in truth)
    kept_hits = sum(p["got"] == "retriangulated" for p in kept)
    return (f"retriangulated recall {hits}/{len(truth)}; without the {len(truth) - len(kept)} copies whose"
            f" area changed by more than {tolerance:.0%}: {kept_hits}/{len(kept)}"
            f" ({kept_hits / len(kept) if kept else float('nan'):.3f})")


def calibration(pairs: list[dict]) -> list[dict]:
    """Per confidence band, the verified pairs (those the gate ruled out without a fit on a row of
    their own: their confidence 1.0 is the gate's, not a measured margin)."""
    edges = [0.5, 0.6, 0.7, 0.8, 0.9, 0.99, 1.0001]
    fitted = [p for p in pairs if p["looked_up"] and not p.get("screened")]
    bands = [(f"[{lo:.2f}, {min(hi, 1.0):.2f}{']' if hi > 1 else ')'}",
              [p for p in fitted if lo <= p["confidence"] < hi])
             for lo, hi in zip(edges[:-1], edges[1:], strict=True)]
    bands.append(("ruled out by the gate", [p for p in pairs if p["looked_up"] and p.get("screened")]))
    return [{"confidence": label, "pairs": len(b), "right": sum(p["got"] == p["truth"] for p in b) / len(b),
             "not similar said": sum(p["got"] != "similar" for p in b)} for label, b in bands if b]


def lookup_cost(fingerprints: np.ndarray, sizes: list[int], rng: np.random.Generator) -> list[dict]:
    """p50/p95 of one k-NN query on n synthetic fingerprints (Gaussian with the measured mean and
    covariance), and the HNSW answer's recall of the exact K neighbours (the service asks K)."""
    import faiss

    mean, cov = fingerprints.mean(axis=0), np.cov(fingerprints.T) + 1e-6 * np.eye(fingerprints.shape[1])
    rows = []
    for n in sizes:
        data = np.abs(rng.multivariate_normal(mean, cov, size=n)).astype(np.float32)
        index = FingerprintIndex()
        t = time.perf_counter()
        index.build(np.arange(n), data)
        build = time.perf_counter() - t
        queries = fingerprints[rng.integers(0, len(fingerprints), 500)]
        times = []
        for q in queries:
            t = time.perf_counter()
            index.search(q[None], K)
            times.append(time.perf_counter() - t)
        exact = faiss.IndexFlatL2(data.shape[1])
        exact.add(data)
        _, truth = exact.search(queries[:200].astype(np.float32), K)
        got, _ = index.search(queries[:200], K)
        recall = np.mean([len(set(a) & set(b)) / K for a, b in zip(got, truth, strict=True)])
        rows.append({"fingerprints": n, "build s": build, "p50 ms": 1e3 * np.percentile(times, 50),
                     "p95 ms": 1e3 * np.percentile(times, 95), "recall@K": float(recall)})
    return rows


def ingest_cost(bases: list[tuple[str, Prepared]], run: Run) -> dict:
    """Per realworld base: describe (the ingest job's numerical work) against the variant step
    (fingerprints of the whole and its objects, lookup, verification of the candidates prepared
    afresh, the worst case: the service keeps prepared candidates in a cache). The service's own
    path, parsing included, with and without that cache: benchmarks/variants_ingest.py."""
    from app.config import Settings
    from app.core.pipeline import describe

    params = Settings().describe.params()
    describe_s = variant_s = 0.0
    for name, p in bases:
        if not name.startswith("real/"):
            continue
        mesh = p.mesh
        t = time.perf_counter()
        describe(mesh, params)
        describe_s += time.perf_counter() - t
        t = time.perf_counter()
        fresh = Prepared(Mesh(mesh.vertices.copy(), mesh.faces.copy()))
        vectors = np.array([fresh.fingerprint] + [q.fingerprint for q in fresh.parts if q is not fresh])
        for i in shortlist(run.index, vectors):
            stored = run.stored[i][1].mesh  # prepared afresh, as the service loads a candidate from its file
            relate(fresh, Prepared(Mesh(stored.vertices, stored.faces)))
        variant_s += time.perf_counter() - t
    return {"describe s": describe_s, "variant step s": variant_s,
            "overhead": variant_s / describe_s if describe_s else float("nan")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--real", type=int, default=6, help="realworld bases (default 6)")
    ap.add_argument("--shrec", type=int, default=6, help="SHREC'11 bases, one per class (default 6)")
    ap.add_argument("--negatives", type=int, default=3, help="hard negatives per SHREC'11 base")
    ap.add_argument("--full", action="store_true", help="all readable realworld meshes, 30 classes")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--lookup-sizes", default="100000",
                    help="synthetic collection sizes for the lookup timing (1000000 builds for minutes)")
    ap.add_argument("--lookup-only", action="store_true", help="only the lookup timing")
    ap.add_argument("--no-ingest", action="store_true", help="skip the describe timing")
    ap.add_argument("--pairs", help="write every pair (truth, verdict, distances) to this JSON file")
    ap.add_argument("--show-errors", action="store_true", help="list every wrong pair")
    ap.add_argument("--tools", choices=("own", "other"), default="own",
                    help="own: the variants of variants_detect_kinds; other: the held-out tools of"
                         " variants_tools (VTK, MeshLab, numpy), no plates")
    ap.add_argument("--held-out", action="store_true",
                    help="bases neither sample the gate's bounds came from picked (6 and 12 per source)")
    args = ap.parse_args(argv)
    import faiss

    faiss.omp_set_num_threads(1)
    rng = np.random.default_rng(args.seed)
    try:  # SHAPEBAG_DATASETS (app/datasets/locate.py): stop, naming what is missing, without them
        realworld, shrec11 = locate.require("realworld"), locate.require("shrec11-simplified")
    except locate.DatasetMissing as exc:
        print(f"variants_detect: {exc}")
        return 2
    real = pick_real(realworld, 10**6 if args.full else args.real,
                     60_000 if args.full else 20_000, args.held_out)
    shrec, negatives = pick_shrec(shrec11, 30 if args.full else args.shrec,
                                  args.negatives, args.held_out)
    bases, dropped = distinct(real + shrec)
    sizes = [int(s) for s in args.lookup_sizes.split(",") if s]
    if args.lookup_only:
        fps = np.array([p.fingerprint for _, p in bases])
        print(table(lookup_cost(fps, sizes, rng), title="candidate lookup, one query, 1 thread"))
        return 0
    run = Run(bases)
    for i, (name, base) in enumerate(bases):
        made = tool_variants(base.mesh, rng) if args.tools == "other" else variants(base.mesh, rng, args.full)
        for kind, mesh, expected in made:
            q = Prepared(mesh)
            truth = mirror_truth(q, base) if kind == "mirror" else expected
            run.query(name, kind, q, {i: truth})
        for neg_name, mesh in negatives.get(name, []):
            run.query(neg_name, "negative", Prepared(mesh), {})
    # every base inside print plates mixing it with other bases
    plates: list[tuple[str, Prepared]] = []
    members: list[set[int]] = []
    for i in range(len(bases) if args.tools == "own" else 0):  # the held-out tools make no plates
        pick = [i, *rng.choice([j for j in range(len(bases)) if j != i], 2, replace=False)]
        others = [bases[j][1].mesh for j in pick[1:]]
        plates.append((f"plate{i}", Prepared(plate_member(bases[i][1].mesh, others, rng))))
        members.append({int(j) for j in pick})
    plate_run = Run(plates)
    for i, (name, prepared) in enumerate(bases if plates else []):
        plate_run.query(name, "in-plate", prepared, {j: "part_of" for j, m in enumerate(members) if i in m})
    pairs = run.pairs + plate_run.pairs
    n_real = sum(n.startswith("real/") for n, _ in bases)
    print(f"{len(bases)} bases ({n_real} realworld), {len(pairs)} pairs;"
          f" dropped as related to an earlier base: {dropped or 'none'}")
    print(table(scores(pairs), title="\nper relation (pairs verified or missed by the lookup)"))
    print(kept_surface(pairs))
    by_kind = defaultdict(list)
    for p in pairs:
        if p["truth"] != "similar" or p["kind"] == "negative":
            by_kind[p["kind"].split(":")[0] if p["kind"].startswith("export") else p["kind"]].append(p)
    print(table([{"kind": k, "pairs": len(v), "right": sum(p["got"] == p["truth"] for p in v) / len(v),
                  "lookup missed": sum(not p["looked_up"] for p in v),
                  "gate ruled out": sum(bool(p["screened"]) for p in v),
                  "area kept <0.9": sum(p["area_ratio"] < 0.9 for p in v)
                  if v[0]["truth"] == "retriangulated" else "-",
                  "said": dict(Counter(p["got"] for p in v))} for k, v in by_kind.items()], title="per kind"))
    negs = [p for p in pairs if p["kind"] == "negative"]
    print(f"hard negatives: {len(negs)} pairs, {sum(p['got'] != 'similar' for p in negs)} called anything but"
          " similar")
    lost = [p for p in pairs if p["fit_without_gate"] is not None]
    print(f"true pairs ruled out by the gate: {len(lost)}, of which the whole-surface fit would have found"
          f" {sum(p['fit_without_gate'] == p['truth'] for p in lost)}\n")
    print(table(calibration(pairs), title="confidence calibration (verified pairs: fraction right)"))
    seconds = {k: run.seconds[k] + plate_run.seconds[k] for k in ("prepare", "lookup", "verify")}
    queries = len({(p["query"], p["kind"]) for p in pairs})
    print(f"per query: prepare {seconds['prepare'] / queries * 1e3:.0f} ms, lookup"
          f" {seconds['lookup'] / queries * 1e3:.2f} ms, verify {seconds['verify'] / queries * 1e3:.0f} ms\n")
    if args.pairs:
        Path(args.pairs).write_text(json.dumps(pairs, indent=1))
    if args.show_errors:
        print(table([p for p in pairs if p["got"] != p["truth"]], title="wrong pairs"))
    if not args.no_ingest:
        print(table([ingest_cost(bases, run)], title="ingest cost on the realworld bases"))
    if sizes:
        fps = np.array([p.fingerprint for _, p in bases] + [p.fingerprint for _, p in plates])
        print(table(lookup_cost(fps, sizes, rng), title="candidate lookup, one query, 1 thread"))
    print(machine())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
