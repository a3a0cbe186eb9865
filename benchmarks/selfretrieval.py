"""Self-retrieval on the realworld corpus: does each real file find itself after a change of mesh?

    python -m benchmarks.selfretrieval                      # the shipped defaults
    python -m benchmarks.selfretrieval --fill-holes 0       # another describe setting, same copies
    python -m benchmarks.selfretrieval --antialias 0 --vocabulary DIR   # no low-pass, another vocabulary
    python -m benchmarks.selfretrieval --files 'oded__*' --jobs 2

The realworld corpus has no labels, but each readable file can be asked to find itself. Two copies of
every file query the collection of originals, encoded with the shipped vocabulary as the service
encodes them (its recorded encoding, fused when it has fusion scales), ranked by the index's L1 and by
the query-adaptive fusion re-rank the service serves (SHAPEBAG_FUSION_RERANK):
- re-triangulated: `benchmarks.variants.retriangulate` (midpoint-subdivided to >= 16k vertices, then
  quadric-decimated to a random 1k-8k): the same surface, another mesh;
- noisy: Gaussian vertex noise, NSR 0.01 (`resolution.perturb`, as `evaluate --noise`).
NN = the copy's nearest original is its own; MRR = mean reciprocal rank of its own; top 5 = its own is
among the first five. Pure BoF is reported beside the fused vector. Each file's copies come from its
own random stream (seed, file name), so a run is reproducible and another setting sees the same copies.
The figures are low by nature: the corpus holds several copies of the same box, and low-poly CAD
reaches 1,000 vertices by subdivision as an original and by decimation as a copy (docs/results.md).
Writes results/<name>.json.
"""

from __future__ import annotations

import argparse
import hashlib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from benchmarks.common import pin_threads, table, write_json
from benchmarks.realworld import CORPUS, corpus_entries, upload_of


def _describe_copies(entry: str, params_kwargs: dict, seed: int) -> dict | None:
    """(child) Original, re-triangulated and noisy descriptions of one corpus entry, or None if refused."""
    from app.config import Settings
    from app.core.mesh import InvalidMeshError
    from app.core.pipeline import DescribeParams, describe
    from app.core.resolution import perturb
    from app.services.mesh_policy import load_upload
    from benchmarks.variants import retriangulate

    data, name = upload_of(Path(entry))
    try:
        mesh = load_upload(data, name, Settings.model_fields["max_vertices"].default)
    except (InvalidMeshError, ValueError):
        return None
    stream = int.from_bytes(hashlib.sha256(f"{seed}:{Path(entry).name}".encode()).digest()[:8], "little")
    rng = np.random.default_rng(stream)
    params = replace(DescribeParams(), **params_kwargs)
    out = {"name": Path(entry).name}
    try:
        out["original"] = describe(mesh, params)
        out["retriangulated"] = describe(retriangulate(mesh, rng), params)
        out["noisy"] = describe(perturb(mesh, 0.01, int(rng.integers(2**63))), params)
    except Exception as exc:  # noqa: BLE001 -- a copy that cannot be described is reported, not fatal
        out["error"] = f"{type(exc).__name__}: {exc}"
    return out


def _rim(description) -> float:
    """The description's free boundary over √area (NaN without a local signature)."""
    return float("nan") if description.local is None else float(description.local.rim)


def scores(queries: np.ndarray, originals: np.ndarray, rerank: tuple[int, float] | None = None,
           rims: np.ndarray | None = None, noises: np.ndarray | None = None) -> dict[str, float]:
    """Query i's own original is originals[i]. queries, originals (n, d) -> NN, MRR, top 5.
    rerank (words, stored Shape-DNA weight): ranked as the service's query-adaptive fusion re-rank
    ranks fused vectors (app.evaluation.adaptive), not by the index's L1, with the queries' rims (q,)
    and input noises (q,)."""
    from app.core.vocabulary import l1_distance
    from app.evaluation import adaptive

    if rerank is None:
        d = l1_distance(queries, originals)  # (n, n)
    else:  # each original's place in each copy's list
        d = adaptive.ranks(queries, originals, np.full(len(queries), -1), *rerank, rims=rims, noises=noises)
    own = np.diagonal(d)[:, None]
    rank = 1 + (d < own).sum(axis=1)  # ties count in the copy's favour, as FAISS's order may
    return {"NN": float(np.mean(rank == 1)), "MRR": float(np.mean(1.0 / rank)),
            "top5": float(np.mean(rank <= 5))}


def run(patterns: list[str], jobs: int, params_kwargs: dict, seed: int,
        vocabulary: Path | None = None, save: Path | None = None) -> dict:
    from app.config import SHIPPED_VOCABULARY
    from app.core.vocabulary import EncodeParams, Vocabulary

    entries = [str(e) for e in corpus_entries(CORPUS, patterns or ["*"])]
    with ProcessPoolExecutor(jobs, mp_context=get_context("spawn"), initializer=pin_threads) as pool:
        described = [r for r in pool.map(_describe_copies, entries, [params_kwargs] * len(entries),
                                         [seed] * len(entries)) if r is not None]
    failed = [r for r in described if "error" in r]
    ok = [r for r in described if "error" not in r]
    vocab = Vocabulary.load(vocabulary or SHIPPED_VOCABULARY)
    recorded = vocab.metadata.get("encode", {})
    fused = EncodeParams().with_encoding(recorded)
    if save is not None:  # the served encoding of every copy, to score ranking rules without describing
        save.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(save, names=np.array([r["name"] for r in ok]), words=vocab.size,
                            stored_weight=vocab.fusion.weight if vocab.fusion is not None else 0.0,
                            **{c: np.stack([vocab.encode(r[c], fused) for r in ok])
                               for c in ("original", "retriangulated", "noisy")},
                            **{f"rim_{c}": np.array([_rim(r[c]) for r in ok])
                               for c in ("original", "retriangulated", "noisy")},
                            **{f"noise_{c}": np.array([r[c].input_noise for r in ok])
                               for c in ("original", "retriangulated", "noisy")})
    lines = {}
    rerank = (vocab.size, vocab.fusion.weight) if vocab.fusion is not None and fused.fusion else None
    for label, enc, order in (("pure BoF", replace(fused, fusion=False), None),
                              ("fused, index order", fused, None),
                              ("fused (served)", fused, rerank)):
        if label == "fused (served)" and order is None:
            continue  # pure-BoF vocabulary: the index's order is what is served
        originals = np.stack([vocab.encode(r["original"], enc) for r in ok])
        for copy in ("retriangulated", "noisy"):
            queries = np.stack([vocab.encode(r[copy], enc) for r in ok])
            rims = np.array([_rim(r[copy]) for r in ok])
            noises = np.array([r[copy].input_noise for r in ok])
            lines[(label, copy)] = scores(queries, originals, order, rims, noises)
    return {"files": len(ok), "refused": len(entries) - len(described), "failed": [(r["name"], r["error"])
            for r in failed], "describe": params_kwargs, "seed": seed,
            "vocabulary": str(vocabulary or "shipped"),
            "lines": {f"{a} | {b}": v for (a, b), v in lines.items()}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--files", action="append", help="glob on the corpus file or folder name (repeatable)")
    ap.add_argument("--jobs", type=int, default=2, help="describing processes")
    ap.add_argument("--seed", type=int, default=0, help="the copies' random streams")
    ap.add_argument("--fill-holes", type=float, default=None, help="DescribeParams.fill_holes override")
    ap.add_argument("--smoothing", type=int, default=None, help="DescribeParams.smoothing override")
    ap.add_argument("--antialias", type=float, default=None,
                    help="DescribeParams.antialias override (0: none)")
    ap.add_argument("--vocabulary", type=Path, default=None,
                    help="a vocabulary directory (default: the shipped)")
    ap.add_argument("--name", default="selfretrieval", help="results/<name>.json")
    ap.add_argument("--save", type=Path, default=None,
                    help="also write the served (fused) vectors of the originals and copies to this .npz")
    a = ap.parse_args(argv)
    overrides = {k: v for k, v in (("fill_holes", a.fill_holes), ("smoothing", a.smoothing),
                                   ("antialias", a.antialias)) if v is not None}
    result = run(a.files or [], a.jobs, overrides, a.seed, a.vocabulary, a.save)
    rows = [{"encoding | copy": name, "NN": v["NN"], "MRR": v["MRR"], "top 5": v["top5"]}
            for name, v in result["lines"].items()]
    print(table(rows))
    print(f"{result['files']} files described (3 ways each), {result['refused']} refused; "
          f"describe overrides {overrides or 'none'}; {len(result['failed'])} copies failed")
    for name, err in result["failed"]:
        print(f"  {name}: {err}")
    print(f"wrote {write_json(a.name, result)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
