"""Partial queries against whole models: the served global ranking, then the partial re-ranking.

    python -m benchmarks.partial_rerank SRC QUERIES [--rerank 100] [--classes N] [--workers 2]

SRC is the labelled folder of whole models (a dataset name under SHAPEBAG_DATASETS, e.g.
`shrec11-simplified`), QUERIES a folder written by benchmarks.partial (labels.csv and partial.csv), or
SRC itself (whole queries: each model finds the others, itself left out). Both are described with the
default DescribeParams through the evaluation cache (.cache/describe), encoded with the shipped
vocabulary (fused, as served), and ranked by L1; a query the service takes for a piece
(app.services.partial.is_partial) has its `--rerank` nearest models re-ranked by the local signatures'
distance (POST /search's candidates also include a coarse pass: `benchmarks.partial_offline --served`).
Prints mAP and NN of both rankings, how many queries were taken for
pieces, the forward / reverse scores of each query's own whole model against the true kept share, and
the CPU time of the re-ranking per query.
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from app.core.partial_match import match_many
from app.core.pipeline import LOCAL, DescribeParams, ShapeDescription
from app.core.vocabulary import Vocabulary
from app.datasets import locate
from app.datasets.folder import read_labelled_folder
from app.evaluation.cache import DescriptionCache, Variant, content_sha256, describe_all, load_descriptions
from app.services.partial import RERANK, is_partial

VOCABULARY = Path(__file__).resolve().parents[1] / "app" / "data" / "vocabulary" / "default"


def average_precision(ranked: np.ndarray, label: str, total: int) -> float:
    """AP of one ranking: ranked (N,) labels in rank order, `total` relevant items in all."""
    relevant = ranked == label
    if total == 0:
        return float("nan")
    hits = np.cumsum(relevant)
    return float((hits[relevant] / (np.flatnonzero(relevant) + 1)).sum() / total)


def _described(folder: Path, classes: set[str] | None, workers: int) -> tuple[list, list[ShapeDescription]]:
    rows = [r for r in read_labelled_folder(folder) if classes is None or r.label in classes]
    files = [(r.path, content_sha256(r.path)) for r in rows]
    params, cache = DescribeParams(), DescriptionCache(".cache/describe")
    describe_all(files, params, cache, workers=workers, label=folder.name)
    return rows, load_descriptions(files, params, cache, Variant())


def _folder(name: str) -> Path:
    path = Path(name)
    if not path.is_dir() and name in locate.KNOWN:
        return locate.require(name)
    return path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src")
    p.add_argument("queries")
    p.add_argument("--rerank", type=int, default=RERANK, help="candidates re-ranked per piece")
    p.add_argument("--classes", type=int, default=0, help="the first N classes only (0: all)")
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args(argv)
    src, qdir = _folder(a.src), _folder(a.queries)
    labels_all = sorted({r.label for r in read_labelled_folder(src)})
    classes = set(labels_all[: a.classes]) if a.classes else None
    models, mdesc = _described(src, classes, a.workers)
    whole = qdir.resolve() == src.resolve()
    queries, qdesc = (models, mdesc) if whole else _described(qdir, classes, a.workers)
    kept: dict[str, float] = {}
    if (qdir / "partial.csv").is_file():
        with open(qdir / "partial.csv", newline="") as fh:
            kept = {row["file"]: float(row["kept_fraction"]) for row in csv.DictReader(fh)}
    vocab = Vocabulary.load(VOCABULARY)
    mvec = np.stack([vocab.encode(d) for d in mdesc]).astype(np.float64)
    labels = np.array([m.label for m in models])
    mname = [m.path.relative_to(src.resolve()).as_posix() for m in models]
    result: dict[str, list[float]] = {"global_ap": [], "global_nn": [], "served_ap": [], "served_nn": []}
    own: list[tuple[float, float, float, float]] = []  # kept, forward, reverse, scale
    pieces, cpu = 0, 0.0
    for qi, (q, d) in enumerate(zip(queries, qdesc, strict=True)):
        dist = np.abs(mvec - vocab.encode(d).astype(np.float64)).sum(axis=1)
        qname = q.path.relative_to(qdir.resolve()).as_posix()
        if whole:
            dist[qi] = np.inf  # a whole query leaves itself out
        order = np.argsort(dist, kind="stable")[: len(models) - whole]
        total = int((labels == q.label).sum()) - whole
        result["global_ap"].append(average_precision(labels[order], q.label, total))
        result["global_nn"].append(float(labels[order[0]] == q.label))
        if is_partial(d.local, None) and d.local is not None:
            pieces += 1
            top = order[: a.rerank]
            t = time.process_time()
            found = match_many(d.local, [sig for j in top if (sig := mdesc[j].local) is not None], LOCAL)
            cpu += time.process_time() - t
            sub = top[np.argsort([m.distance for m in found], kind="stable")]
            order = np.concatenate([sub, order[a.rerank:]])
            for j, m in zip(top, found, strict=True):
                if mname[j] == qname and qname in kept:
                    own.append((kept[qname], m.forward, m.reverse, m.scale))
        result["served_ap"].append(average_precision(labels[order], q.label, total))
        result["served_nn"].append(float(labels[order[0]] == q.label))
    print(f"{len(queries)} queries ({qdir.name}) against {len(models)} models ({src.name}), "
          f"{len(set(labels))} classes; re-rank {a.rerank}; local grid {LOCAL}")
    print(f"  taken for pieces: {pieces}/{len(queries)}")
    for name in ("global", "served"):
        print(f"  {name:7s} mAP {100 * np.nanmean(result[name + '_ap']):6.2f}  "
              f"NN {np.mean(result[name + '_nn']):.3f}")
    if pieces:
        print(f"  re-ranking: {1000 * cpu / pieces:.0f} ms CPU per piece ({a.rerank} candidates)")
    if own:
        o = np.array(own)
        print(f"  own whole in the candidates: {len(o)}/{pieces}; kept {o[:, 0].mean():.3f}, forward "
              f"{o[:, 1].mean():.3f}, reverse {o[:, 2].mean():.3f} (|reverse - kept| "
              f"{np.abs(o[:, 2] - o[:, 0]).mean():.3f}, corr {np.corrcoef(o[:, 0], o[:, 2])[0, 1]:.3f}); "
              f"scale {o[:, 3].mean():.3f} (|scale - kept| {np.abs(o[:, 3] - o[:, 0]).mean():.3f})")
        for lo in np.arange(0.4, 0.85, 0.05):
            band = (o[:, 0] >= lo) & (o[:, 0] < lo + 0.05)
            if band.any():
                print(f"    kept {lo:.2f}-{lo + 0.05:.2f}: n {band.sum():3d}  "
                      f"forward {o[band, 1].mean():.3f}  reverse {o[band, 2].mean():.3f}  "
                      f"scale {o[band, 3].mean():.3f}")
    size = sum(v.nbytes for v in (mdesc[0].local.slopes, mdesc[0].local.area, mdesc[0].local.valid)) \
        if mdesc[0].local is not None else 0
    print(f"  local signature: {size} bytes per model in memory")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
