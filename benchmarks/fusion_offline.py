"""Fusion rules scored offline from cached descriptions (issue 30: fusion that never loses to its parts).

    python -m benchmarks.fusion_offline [--cache DIR] [--vocabulary V] [--candidates 100] [COLUMN ...]

COLUMN is `FOLDER` (the collection against itself), `FOLDER@NSR` (noisy queries against the clean
collection, the `shapebag evaluate --noise` cache entries of seed 0) or `FOLDER~QUERIES` (another
folder's meshes as queries, their counterparts left out, as `--queries` does). Without columns: every
column of docs/results.md (var/... and $SHAPEBAG_DATASETS/shrec11-simplified). DIR holds the cached
descriptions, `<file sha256>[.noise<nsr>-s0].npz`; it defaults to this code's key under
.cache/describe. A column with a missing cache file is named and skipped, never described here.

Per column, mAP % (and NN) of: the BoF part alone, the Shape-DNA line of `shapebag evaluate` (L2),
the served fusion (BoF + 1 × DNA, each over its scale), reciprocal-rank fusion, per-query local
scaling, and the query-adaptive re-rank of app.core.fusion twice: over whole rows (`adaptive/all`)
and as served (`adaptive`: candidates are the union of two fused-index searches of N each, the query
and the expanded query; what is outside them follows in the served order), and `adaptive+pieces`,
the service's ranking: the same with a query that has a rim (an open scan, a piece) ranked as a piece
(app.core.piece_rank). The last line is each rule's worst margin against the better of BoF and
Shape-DNA.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.core import fusion
from app.core.baselines import euclidean_distance, shape_dna
from app.core.meshdata import InvalidMeshError
from app.core.pipeline import DescribeParams, ShapeDescription
from app.core.roughness import displacement_correlation
from app.core.vocabulary import EncodeParams, Vocabulary, l1_distance
from app.evaluation import adaptive, sets
from app.evaluation.cache import DescriptionCache, Variant, load_variant

SHREC = "shrec11-simplified"


def default_columns(var: Path, datasets: Path) -> list[str]:
    """The columns of docs/results.md, made by benchmarks.highres/scans/rigid/variants under `var`."""
    shrec = datasets / SHREC
    return [
        *(f"{var / c}{n}" for c in ("fine", "kinchars", "chars") for n in ("", "@0.0001", "@0.01")),
        str(var / "scans"), str(var / "rigid"),
        str(var / "synthetic-8x12-s1"), f"{var / 'synthetic-8x12-s1'}@0.01",
        str(shrec), f"{shrec}@0.01", f"{shrec}~{var / 'shrec11-remesh'}",
    ]


@dataclass
class Column:
    name: str
    labels: np.ndarray  # (N,) database classes
    query_labels: np.ndarray  # (q,)
    left_out: np.ndarray  # (q,) database index left out of each query's ranking, or all -1
    db: np.ndarray  # (N, v + c) fused vectors as stored
    queries: np.ndarray  # (q, v + c)
    db_dna: np.ndarray  # (N, c) raw Shape-DNA (the evaluate line's L2)
    query_dna: np.ndarray  # (q, c)
    query_rims: np.ndarray  # (q,) free boundary over √area (NaN: no local signature)
    query_noises: np.ndarray  # (q,) input displacement correlation (measured from the mesh if not stored)
    db_locals: list = field(default_factory=list)  # (N,) local signatures (None: none stored)
    query_locals: list = field(default_factory=list)  # (q,)


def _load(folder: sets.Folder, cache: Path, variant: Variant, vocab: Vocabulary) -> tuple | None:
    paths = [cache / f"{sha}{variant.suffix()}.npz" for _, sha in folder.files]
    missing = sum(not p.exists() for p in paths)
    if missing:
        print(f"  {folder.root.name}{variant.suffix()}: {missing} of {len(paths)} not cached, skipped")
        return None
    descs = [ShapeDescription.load(p) for p in paths]
    fused = np.stack([vocab.encode(d, EncodeParams()) for d in descs])
    noises = adaptive.noises_of(descs)
    for i in np.flatnonzero(np.isnan(noises)):  # saved before descriptions recorded it: the same measure
        path, sha = folder.files[i]
        with contextlib.suppress(InvalidMeshError, ValueError):  # unreadable now: unknown, weighed as clean
            noises[i] = displacement_correlation(load_variant(str(path), sha, variant))
    return (fused, np.stack([shape_dna(d.eigenvalues) for d in descs]), adaptive.rims_of(descs), noises,
            [d.local for d in descs])


def load_column(spec: str, cache: Path, vocab: Vocabulary) -> Column | None:
    folder_spec, _, noise = spec.partition("@")
    folder_spec, _, query_dir = folder_spec.partition("~")
    folder = sets.read_folder(folder_spec)
    base = _load(folder, cache, Variant(), vocab)
    if base is None:
        return None
    n = len(folder.labels)
    if query_dir:
        other = sets.read_folder(query_dir)
        q = _load(other, cache, Variant(), vocab)
        if q is None:
            return None
        pairs = sets.counterparts(folder, other)
        return Column(spec, folder.labels, other.labels, pairs, base[0], q[0], base[1], q[1], q[2], q[3],
                      base[4], q[4])
    q = _load(folder, cache, Variant(float(noise), 0), vocab) if noise else base
    if q is None:
        return None
    return Column(spec, folder.labels, folder.labels, np.arange(n), base[0], q[0], base[1], q[1], q[2], q[3],
                  base[4], q[4])


def scores(distances: np.ndarray, col: Column) -> tuple[float, float]:
    """(q, N) distances -> (mAP %, NN %), each query's left-out shape not ranked."""
    result = sets.cross_scores(distances, col.query_labels, col.labels, col.left_out)[0]
    return result["mAP"] * 100, result["NN"] * 100


def _masked(d: np.ndarray, col: Column) -> np.ndarray:
    d = np.array(d, dtype=np.float64)
    rows = np.flatnonzero(col.left_out >= 0)
    d[rows, col.left_out[rows]] = np.inf
    return d


def ranks(d: np.ndarray) -> np.ndarray:
    return np.argsort(np.argsort(d, axis=1, kind="stable"), axis=1, kind="stable").astype(np.float64)


def served_adaptive(
    col: Column, words: int, stored: float, rule: fusion.AdaptiveRule, n_cand: int, pieces: bool = False
) -> np.ndarray:
    """(q, N) as served (app.evaluation.adaptive: brute-force L1 for the index); pieces: a query with a
    rim ranked as a piece, as the service does (slower: a partial match per candidate)."""
    locals_ = (col.query_locals, col.db_locals) if pieces else (None, None)
    return _masked(adaptive.ranks(col.queries, col.db, col.left_out, words, stored, rule, n_cand,
                                  col.query_rims, col.query_noises, *locals_), col)


def full_adaptive(col: Column, words: int, stored: float, rule: fusion.AdaptiveRule) -> np.ndarray:
    """(q, N): the same rule over every database shape (no candidate limit)."""
    out = np.empty((len(col.queries), len(col.db)))
    for i, q in enumerate(col.queries):
        keep = np.setdiff1d(np.arange(len(col.db)), [col.left_out[i]])
        w, expanded = fusion.adaptive_query(q, col.db[keep], words, stored, rule, float(col.query_rims[i]),
                                            float(col.query_noises[i]))
        out[i, keep] = fusion.adaptive_distances(expanded, w, col.db[keep], words, stored)
    return _masked(out, col)


def rules(words: int, stored: float, rule: fusion.AdaptiveRule, n_cand: int) -> dict[str, Callable]:
    def parts(col: Column) -> tuple[np.ndarray, np.ndarray]:
        qb, qd = fusion.split_parts(col.queries, words, stored)
        cb, cd = fusion.split_parts(col.db, words, stored)
        return _masked(l1_distance(qb, cb), col), _masked(l1_distance(qd, cd), col)

    def local(col: Column, k: int = 10) -> np.ndarray:
        b, d = parts(col)
        k = min(k, b.shape[1] - 1)  # a small column: its farthest shape but the left-out one
        return b / np.sort(b, axis=1)[:, k - 1:k] + d / np.sort(d, axis=1)[:, k - 1:k]

    return {
        "BoF": lambda col: parts(col)[0],
        "DNA": lambda col: euclidean_distance(col.query_dna, col.db_dna),
        "DNA part": lambda col: parts(col)[1],
        "served": lambda col: l1_distance(col.queries, col.db),
        "RRF 60": lambda col: -sum(1.0 / (60 + ranks(p)) for p in parts(col)),
        "local 10": local,
        "adaptive/all": lambda col: full_adaptive(col, words, stored, rule),
        "adaptive": lambda col: served_adaptive(col, words, stored, rule, n_cand),
        "adaptive+pieces": lambda col: served_adaptive(col, words, stored, rule, n_cand, pieces=True),
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("columns", nargs="*")
    ap.add_argument("--cache", help="the folder of cached descriptions (default: this code's key)")
    ap.add_argument("--vocabulary", default="app/data/vocabulary/default")
    ap.add_argument("--candidates", type=int, default=100, help="N of each fused-index search")
    ap.add_argument("--var", default="var", help="where the generated columns are")
    args = ap.parse_args(argv)
    datasets = Path(os.environ.get("SHAPEBAG_DATASETS", "../shared/datasets"))
    columns = args.columns or default_columns(Path(args.var), datasets)
    cache = Path(args.cache) if args.cache else DescriptionCache(".cache/describe").description_path(
        "x", DescribeParams(), Variant()).parent
    vocab = Vocabulary.load(args.vocabulary)
    if vocab.fusion is None:
        raise SystemExit(f"{args.vocabulary} has no fusion scales")
    table = rules(vocab.size, vocab.fusion.weight, fusion.AdaptiveRule(), args.candidates)
    print(f"cache {cache}, vocabulary {args.vocabulary}, {fusion.AdaptiveRule()}, N = {args.candidates}")
    print("column".ljust(44) + "".join(name.rjust(16) for name in table) + "   seconds")
    worst = {name: np.inf for name in table}
    for spec in columns:
        t = time.perf_counter()
        col = load_column(spec, cache, vocab)
        if col is None:
            continue
        got = {name: scores(f(col), col) for name, f in table.items()}
        best = max(got["BoF"][0], got["DNA"][0])
        for name, (m, _) in got.items():
            worst[name] = min(worst[name], m - best)
        cells = "".join(f"{m:9.2f} ({nn:3.0f})" for m, nn in got.values())
        print(f"{spec[-44:]:44}{cells}   {time.perf_counter() - t:6.1f}", flush=True)
    print("worst against max(BoF, DNA)".ljust(44) + "".join(f"{v:16.2f}" for v in worst.values()))


if __name__ == "__main__":
    main()
