"""Partial re-ranking ideas in seconds: per-sample nearest distances computed once, aggregations tried.

    python -m benchmarks.partial_offline SRC QUERIES --out var/spec [--rerank 200] [--classes a,b]
    python -m benchmarks.partial_offline SRC QUERIES --out var/spec --served [--every 6]

Reads the eigenpairs that `benchmarks.partial_spectra cache` stored under --out, builds each mesh's fused
global vector (shipped vocabulary) and local signature (app.core.partial, LOCAL), and, for every query,
the nearest model sample of each trusted query sample under every scale hypothesis, for the global
top N: the (shifts, p, N) table from which app.core.partial_match's distance, forward and reverse are
aggregated. These tables are kept in memory (about 1 GB for 600 queries and N = 200), so each way of
aggregating them into a ranking costs seconds; `RANKINGS` names the ones printed (mAP / NN), with the
diagnostics of the first hits (is the own class among the candidates, at which rank is the first one).
`--served` instead compares, query by query, the re-ranking of the global top 200 with the service's
candidates (app.services.partial: the global top GLOBAL_KEEP and the COARSE_KEEP nearest by the coarse
pass over every model), each re-ranked by the full partial distance, and prints the calibration.
"""

from __future__ import annotations

import argparse
import csv
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.partial import LocalSignature
from app.core.partial_match import CAP, MIN_SLOPES, head, match_many
from app.core.pipeline import LOCAL
from app.core.vocabulary import Vocabulary
from app.datasets.folder import read_labelled_folder
from benchmarks.partial_rerank import VOCABULARY, average_precision
from benchmarks.partial_spectra import _folder, _key, _load


@dataclass
class Pairs:
    """One query against its global top N.

    top     : (N,) model indices in global order
    glob    : (N,) global L1 distances
    nearest : (shifts, p, N) float32 nearest squared slope distance of each query sample (inf where the
              sample is not trusted under that shift)
    back    : (shifts, N, s) float32 nearest trusted query sample of each model sample
    qarea   : (shifts, p) area share of each trusted query sample (0 where not trusted; rows sum to 1)
    """

    top: np.ndarray
    glob: np.ndarray
    nearest: np.ndarray
    back: np.ndarray
    qarea: np.ndarray


def _sq32(q: np.ndarray, qvalid: np.ndarray, m: np.ndarray) -> np.ndarray:
    """app.core.partial_match._sq_distances in float32 (a tenth of the time; the rankings agree)."""
    out = np.empty((len(q), len(m)), dtype=np.float32)
    mm = (m.astype(np.float32) ** 2).cumsum(axis=1)  # (S, J) squared norms of every prefix
    for length in np.unique(qvalid):
        rows = qvalid == length
        a, b = q[rows, :length].astype(np.float32), m[:, :length].astype(np.float32)
        d = (a * a).sum(1)[:, None] + mm[None, :, length - 1] - 2.0 * (a @ b.T)
        out[rows] = np.maximum(d, 0.0) / length
    return out


def pairs(query: LocalSignature, models: list[LocalSignature], top: np.ndarray, glob: np.ndarray) -> Pairs:
    width, shifts = LOCAL.slopes, LOCAL.shifts
    stacked = np.concatenate([models[j].slopes[:, :width] for j in top])  # (N s, J)
    s = models[top[0]].slopes.shape[0]
    p = len(query.slopes)
    nearest = np.full((shifts, p, len(top)), np.inf, dtype=np.float32)
    back = np.full((shifts, len(top), s), np.inf, dtype=np.float32)
    qarea = np.zeros((shifts, p))
    for shift in range(shifts):
        qvalid = np.minimum(query.valid.astype(np.int64) - shift, width)
        rows = qvalid >= MIN_SLOPES
        if not rows.any():
            continue
        d = _sq32(query.slopes[rows, shift:shift + width], qvalid[rows], stacked)  # (p', N s)
        d = d.reshape(len(d), len(top), s)
        nearest[shift, rows] = d.min(axis=2)
        back[shift] = d.min(axis=0)
        qa = query.area[rows].astype(np.float64)
        qarea[shift, rows] = qa / qa.sum()
    return Pairs(top=top, glob=glob, nearest=nearest, back=back, qarea=qarea)


def served(pr: Pairs, marea: np.ndarray) -> np.ndarray:
    """(N,) app.core.partial_match's distance: per shift the area-weighted capped nearest, min over shifts."""
    near = np.where(np.isfinite(pr.nearest), np.minimum(pr.nearest, CAP), 0.0)
    scores = np.einsum("sp,spn->sn", pr.qarea, near)
    scores[pr.qarea.sum(axis=1) == 0] = np.inf
    return scores.min(axis=0)


RANKINGS: dict[str, Callable[[Pairs, np.ndarray], np.ndarray]] = {"served": served}


@dataclass
class Bundle:
    """Everything a ranking needs: labels (M,), qlabels (Q,), kept (Q,) true kept shares, qnames and
    mnames (relative files), marea (M, s) model sample areas, orders (Q, M) global orders, pairs (Q,)."""

    labels: np.ndarray
    qlabels: np.ndarray
    kept: np.ndarray
    qnames: list[str]
    mnames: list[str]
    marea: np.ndarray
    orders: np.ndarray
    pairs: list[Pairs]


def build(src: Path, qdir: Path, out: Path, rerank: int, classes: set[str] | None,
          every: int = 1) -> Bundle:
    """The candidates' tables of every `every`-th query of qdir (classes: those only, models too)."""
    vocab = Vocabulary.load(VOCABULARY)
    rows = [r for r in read_labelled_folder(src) if classes is None or r.label in classes]
    qrows = [r for r in read_labelled_folder(qdir) if classes is None or r.label in classes][::every]
    models = [_load(out / f"{_key(src, r.path)}.npz", vocab, LOCAL) for r in rows]
    with open(qdir / "partial.csv", newline="") as fh:
        kept = {row["file"]: float(row["kept_fraction"]) for row in csv.DictReader(fh)}
    mvec = np.stack([m[0] for m in models])
    msig = [m[1] for m in models]
    orders, table = [], []
    for r in qrows:
        vec, local = _load(out / f"{_key(qdir, r.path)}.npz", vocab, LOCAL)
        dist = np.abs(mvec - vec).sum(axis=1)
        order = np.argsort(dist, kind="stable")
        orders.append(order)
        table.append(pairs(local, msig, order[:rerank], dist[order[:rerank]]))
    qnames = [r.path.relative_to(qdir.resolve()).as_posix() for r in qrows]
    return Bundle(labels=np.array([r.label for r in rows]), qlabels=np.array([r.label for r in qrows]),
                  kept=np.array([kept[n] for n in qnames]), qnames=qnames,
                  mnames=[r.path.relative_to(src.resolve()).as_posix() for r in rows],
                  marea=np.stack([m.area for m in msig]).astype(np.float64), orders=np.stack(orders),
                  pairs=table)


def evaluate(b: Bundle, rank: Callable[[Pairs, np.ndarray], np.ndarray]) -> tuple[float, float]:
    """(mAP, NN) of re-ranking each query's candidates by rank(pairs, marea) (lower first)."""
    ap, nn = [], []
    for label, order, pr in zip(b.qlabels, b.orders, b.pairs, strict=True):
        head = pr.top[np.argsort(rank(pr, b.marea[pr.top]), kind="stable")]
        ranked = b.labels[np.concatenate([head, order[len(pr.top):]])]
        ap.append(average_precision(ranked, label, int((b.labels == label).sum())))
        nn.append(float(ranked[0] == label))
    return 100 * float(np.mean(ap)), float(np.mean(nn))


def recall(b: Bundle) -> float:
    """Share of the queries with a model of their class among the candidates: the NN a re-ranking of
    them can reach at most."""
    return float(np.mean([(b.labels[pr.top] == label).any() for label, pr in zip(b.qlabels, b.pairs,
                                                                                strict=True)]))


def calibration(src: Path, qdir: Path, out: Path, every: int = 1) -> np.ndarray:
    """(Q, 4) kept share, forward, reverse and scale of each piece against its own whole model."""
    with open(qdir / "partial.csv", newline="") as fh:
        kept = {row["file"]: float(row["kept_fraction"]) for row in csv.DictReader(fh)}
    vocab, rows = Vocabulary.load(VOCABULARY), []
    for r in read_labelled_folder(qdir)[::every]:
        name = r.path.relative_to(qdir.resolve()).as_posix()
        whole = _load(out / f"{_key(src, src.resolve() / name)}.npz", vocab, LOCAL)[1]
        (m,) = match_many(_load(out / f"{_key(qdir, r.path)}.npz", vocab, LOCAL)[1], [whole], LOCAL)
        rows.append((kept[name], m.forward, m.reverse, m.scale))
    return np.array(rows)


def print_calibration(own: np.ndarray, lo: float, hi: float) -> None:
    print(f"  own whole: kept {own[:, 0].mean():.3f}, forward {own[:, 1].mean():.3f}, reverse "
          f"{own[:, 2].mean():.3f} (corr {np.corrcoef(own[:, 0], own[:, 2])[0, 1]:.2f}, |reverse - kept| "
          f"{np.abs(own[:, 2] - own[:, 0]).mean():.3f}), |scale - kept| "
          f"{np.abs(own[:, 3] - own[:, 0]).mean():.3f}")
    for a in np.arange(lo, hi - 1e-9, 0.05):
        band = (own[:, 0] >= a) & (own[:, 0] < a + 0.05)
        if band.any():
            print(f"    kept {a:.2f}-{a + 0.05:.2f}: n {band.sum():3d}  forward {own[band, 1].mean():.3f}  "
                  f"reverse {own[band, 2].mean():.3f}  scale {own[band, 3].mean():.3f}")


def served_figures(src: Path, qdir: Path, out: Path, every: int) -> None:
    """mAP / NN and candidate recall of the global top 200 and of the service's candidates, re-ranked."""
    from app.services.partial import COARSE_KEEP, COARSE_POINTS, GLOBAL_KEEP, RERANK

    vocab = Vocabulary.load(VOCABULARY)
    rows = read_labelled_folder(src)
    models = [_load(out / f"{_key(src, r.path)}.npz", vocab, LOCAL) for r in rows]
    mvec, msig = np.stack([m[0] for m in models]), [m[1] for m in models]
    labels = np.array([r.label for r in rows])
    res: dict[str, list[float]] = {f"{n}_{k}": [] for n in ("global", "served") for k in ("ap", "nn", "rec")}
    for r in read_labelled_folder(qdir)[::every]:
        vec, local = _load(out / f"{_key(qdir, r.path)}.npz", vocab, LOCAL)
        order = np.argsort(np.abs(mvec - vec).sum(axis=1), kind="stable")
        coarse = served(pairs(head(local, COARSE_POINTS), msig, order, order), None)
        near = set(order[np.argsort(coarse, kind="stable")[:COARSE_KEEP]].tolist())
        chosen = order[[j < GLOBAL_KEEP or int(m) in near for j, m in enumerate(order)]]
        for name, cand in (("global", order[:RERANK]), ("served", chosen)):
            headed = cand[np.argsort(served(pairs(local, msig, cand, cand), None), kind="stable")]
            ranked = labels[np.concatenate([headed, order[~np.isin(order, cand)]])]
            res[f"{name}_ap"].append(100 * average_precision(ranked, r.label, int((labels == r.label).sum())))
            res[f"{name}_nn"].append(float(ranked[0] == r.label))
            res[f"{name}_rec"].append(float((labels[cand] == r.label).any()))
    print(f"{len(res['global_ap'])} pieces ({qdir.name}, every {every}) against {len(rows)} models")
    for name in ("global", "served"):
        ap, nn, rec = (np.mean(res[f"{name}_{k}"]) for k in ("ap", "nn", "rec"))
        print(f"  {name} candidates: mAP {ap:6.2f}  NN {nn:.3f}  own class among them {rec:.3f}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src")
    p.add_argument("queries")
    p.add_argument("--out", type=Path, default=Path("var/spec"))
    p.add_argument("--rerank", type=int, default=200)
    p.add_argument("--classes", default="")
    p.add_argument("--every", type=int, default=1, help="every n-th query only (a quick look)")
    p.add_argument("--served", action="store_true", help="the service's candidates against the top 200")
    a = p.parse_args(argv)
    if a.served:
        served_figures(_folder(a.src), _folder(a.queries), a.out, a.every)
        own = calibration(_folder(a.src), _folder(a.queries), a.out, a.every)
        print_calibration(own, 0.4 if own[:, 0].min() < 0.6 else 0.6, 0.85)
        return 0
    classes = set(a.classes.split(",")) if a.classes else None
    b = build(_folder(a.src), _folder(a.queries), a.out, a.rerank, classes, a.every)
    print(f"{len(b.qlabels)} pieces ({a.queries}, mean kept {b.kept.mean():.3f}) against {len(b.labels)} "
          f"models; re-rank {a.rerank}")
    print(f"  own class among the candidates: {recall(b):.3f}")
    for name, rank in RANKINGS.items():
        m, n = evaluate(b, rank)
        print(f"  {name:16s} mAP {m:6.2f}  NN {n:.3f}")
    own = calibration(_folder(a.src), _folder(a.queries), a.out, a.every)
    print_calibration(own, 0.4 if own[:, 0].min() < 0.6 else 0.6, 0.85)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
