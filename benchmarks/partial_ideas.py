"""Ideas for a piece's first hit (NN at 60-85 %), scored on the served candidates in seconds each.

    python -m benchmarks.partial_ideas SRC QUERIES --out var/spec --start 0 --every 6   # pick on these
    python -m benchmarks.partial_ideas SRC QUERIES --out var/spec --start 3 --every 6   # held out
    python -m benchmarks.partial_ideas SRC QUERIES --out var/spec --start 0 --every 6 --complement
           [--classes laptop,octopus,...] [--spaces slopes,whitened,level2]

Reads the eigenpairs `benchmarks.partial_spectra cache` stored (cache every 3rd piece for both splits).
For each piece, the served candidates (app.services.partial: the global top GLOBAL_KEEP and the
COARSE_KEEP nearest by the coarse pass) and, per scale hypothesis, the nearest model sample of each query
sample AND the nearest query sample of each model sample (distances and indices) in three feature
spaces: the served slopes; the slopes whitened by the model samples' covariance (a Cholesky factor, so a
prefix of whitened slopes depends only on the same prefix of slopes and the rim's trust carries over);
the slopes plus the level log(t K_t(x, x)) at the window's first time (the HKS value, scale-normalised:
t K_t is unchanged when a surface scaled by s is read at s² t). Then each ranking below aggregates the
tables: mutual nearest matches, a vote of each query sample's best candidates, the model's cost back to
the query over the share the scale implies. Prints mAP / NN of each, and the wrong first hits' classes.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.partial import LocalSignature
from app.core.partial_match import CAP, MIN_SLOPES, TOLERANCE, head
from app.core.pipeline import LOCAL
from app.core.vocabulary import Vocabulary
from app.datasets.folder import read_labelled_folder
from app.services.partial import COARSE_KEEP, COARSE_POINTS, GLOBAL_KEEP
from benchmarks.partial_offline import pairs, served
from benchmarks.partial_rerank import VOCABULARY, average_precision
from benchmarks.partial_spectra import _folder, _key, load_with_spectrum

FAR = np.float32(1e30)


@dataclass
class Shape:
    vec: np.ndarray  # (v,) fused global vector
    sig: LocalSignature
    level: np.ndarray  # (p, T) log(t K_t(x, x)) of each sample at the query grid's T times


def load(path: Path, vocab: Vocabulary) -> Shape:
    """partial_spectra's entry, plus the samples' levels."""
    vec, sig, spectrum = load_with_spectrum(path, vocab, LOCAL)
    assert sig.vertex is not None
    grid = LOCAL.times(LOCAL.shifts - 1)
    k = (spectrum.eigenvectors[sig.vertex] ** 2) @ np.exp(-np.outer(spectrum.eigenvalues, grid))
    return Shape(vec, sig, np.log(np.maximum(k, 1e-300) * grid))


@dataclass
class Table:
    """One piece against its candidates (N), per scale hypothesis (shifts) in one feature space.

    near (shifts, p, N) nearest distance of each query sample (inf: untrusted), near_i its model sample;
    back (shifts, N, s) nearest trusted query sample's distance of each model sample, back_i its index;
    qarea (shifts, p) trusted query area (rows sum to 1)."""

    near: np.ndarray
    near_i: np.ndarray
    back: np.ndarray
    back_i: np.ndarray
    qarea: np.ndarray


def table(q: Shape, models: list[Shape], cand: np.ndarray, whiten: np.ndarray | None,
          alpha: float) -> Table:
    width, shifts = LOCAL.slopes, LOCAL.shifts
    s = len(models[0].sig.slopes)
    m_sl = np.concatenate([models[j].sig.slopes[:, :width] for j in cand]).astype(np.float32)  # (N s, J)
    m_ok = np.concatenate([models[j].sig.valid >= MIN_SLOPES for j in cand])
    m_lv = np.concatenate([models[j].level[:, 0] for j in cand])
    if whiten is not None:
        m_sl = m_sl @ whiten.T.astype(np.float32)
    m_sq = (m_sl * m_sl).cumsum(axis=1)  # (N s, J) squared norms of every prefix
    m_sq[~m_ok] = FAR  # a rim sample is never a nearest sample
    p, n = len(q.sig.slopes), len(cand)
    out = Table(np.full((shifts, p, n), np.inf, np.float32), np.zeros((shifts, p, n), np.int16),
                np.full((shifts, n, s), np.inf, np.float32), np.zeros((shifts, n, s), np.int16),
                np.zeros((shifts, p)))
    for shift in range(shifts):
        qvalid = np.minimum(q.sig.valid.astype(np.int64) - shift, width)
        rows = np.flatnonzero(qvalid >= MIN_SLOPES)
        if not len(rows):
            continue
        qs = q.sig.slopes[rows, shift:shift + width].astype(np.float32)
        if whiten is not None:
            qs = qs @ whiten.T.astype(np.float32)  # lower triangular: a prefix stays a prefix
        d = np.empty((len(rows), len(m_sl)), np.float32)
        for length in np.unique(qvalid[rows]):  # float32, as partial_offline's tables (rankings agree)
            r = qvalid[rows] == length
            a = qs[r, :length]
            prod = a @ m_sl[:, :length].T
            d[r] = np.maximum((a * a).sum(1)[:, None] + m_sq[None, :, length - 1] - 2 * prod, 0) / length
        if alpha:
            d += (alpha * (q.level[rows, shift][:, None] - m_lv[None]) ** 2).astype(np.float32)
        d3 = d.reshape(len(rows), n, s)
        i = d3.argmin(axis=2)
        out.near[shift, rows] = np.take_along_axis(d3, i[:, :, None], axis=2)[:, :, 0]
        out.near_i[shift, rows] = i
        i = d3.argmin(axis=0)
        out.back[shift] = np.take_along_axis(d3, i[None], axis=0)[0]
        out.back_i[shift] = rows[i]
        qa = q.sig.area[rows].astype(np.float64)
        out.qarea[shift, rows] = qa / qa.sum()
    out.near[out.near > FAR / 100] = np.inf  # a model with no trusted sample
    out.back[out.back > FAR / 100] = np.inf
    return out


def _scores(t: Table, cap: float) -> np.ndarray:
    """(shifts, N) the served aggregation per scale hypothesis."""
    near = np.where(np.isfinite(t.near), np.minimum(t.near, cap), 0.0)
    sc = np.einsum("sp,spn->sn", t.qarea, near)
    sc[t.qarea.sum(axis=1) == 0] = np.inf
    return sc


def r_served(t: Table, cap: float, marea: np.ndarray) -> np.ndarray:
    return _scores(t, cap).min(axis=0)


def mutual(t: Table, best: np.ndarray) -> np.ndarray:
    """(N,) trusted query area whose nearest model sample has it as its nearest, at each model's best
    scale."""
    cols = np.arange(t.near.shape[2])
    ni = t.near_i[best, :, cols]  # (N, p)
    nb = t.back_i[best[:, None], cols[:, None], ni]  # (N, p) the back match of each query's match
    ok = (nb == np.arange(t.near.shape[1])[None]) & np.isfinite(t.near[best, :, cols])
    return (t.qarea[best] * ok).sum(axis=1)


def vote(t: Table, best: np.ndarray, top: int) -> np.ndarray:
    """(N,) trusted query area for which this model is among its `top` nearest candidates (at each
    model's best scale)."""
    cols = np.arange(t.near.shape[2])
    d = t.near[best, :, cols].T  # (p, N)
    rank = np.argsort(np.argsort(d, axis=1, kind="stable"), axis=1)
    good = (rank < top) & np.isfinite(d)
    return (t.qarea[best].T * good).sum(axis=0)


def backcost(t: Table, best: np.ndarray, cap: float, marea: np.ndarray) -> np.ndarray:
    """(N,) the model samples' capped cost back to the query, area-weighted over the best-matched
    share of the model that the scale implies."""
    share = LOCAL.ratio ** -best.astype(float)
    cols = np.arange(t.near.shape[2])
    b = np.minimum(t.back[best, cols], cap)  # (N, s)
    out = np.empty(len(cols))
    for c in cols:
        order = np.argsort(b[c])
        a = marea[c][order] / marea[c].sum()
        keep = np.cumsum(a) - a < share[c]
        out[c] = (a[keep] * b[c][order][keep]).sum() / a[keep].sum()
    return out


Rank = Callable[[Table, float, np.ndarray], np.ndarray]


def _best(t: Table, cap: float) -> tuple[np.ndarray, np.ndarray]:
    """(N,) the served distance and (N,) the scale hypothesis it is at."""
    sc = _scores(t, cap)
    return sc.min(axis=0), sc.argmin(axis=0)


def _mutual(lam: float) -> Rank:
    def rank(t: Table, cap: float, marea: np.ndarray) -> np.ndarray:
        score, best = _best(t, cap)
        return score - lam * cap * mutual(t, best)
    return rank


def _vote(top: int, lam: float | None) -> Rank:
    def rank(t: Table, cap: float, marea: np.ndarray) -> np.ndarray:
        score, best = _best(t, cap)
        votes = vote(t, best, top)
        return -votes if lam is None else score - lam * cap * votes
    return rank


def _back(lam: float) -> Rank:
    def rank(t: Table, cap: float, marea: np.ndarray) -> np.ndarray:
        score, best = _best(t, cap)
        return score + lam * backcost(t, best, cap, marea)
    return rank


def _mutual_vote(lam: float, top: int, mu: float) -> Rank:
    def rank(t: Table, cap: float, marea: np.ndarray) -> np.ndarray:
        score, best = _best(t, cap)
        return score - lam * cap * mutual(t, best) - mu * cap * vote(t, best, top)
    return rank


def rankings() -> dict[str, Rank]:
    out: dict[str, Rank] = {"served": r_served}
    out.update({f"mutual {lam}": _mutual(lam) for lam in (0.5, 1.0, 2.0, 4.0, 1e6)})
    out["vote 10"] = _vote(10, None)
    out["served+vote 10 0.5"] = _vote(10, 0.5)
    out["mutual 1 + vote 10 0.5"] = _mutual_vote(1.0, 10, 0.5)
    out.update({f"back {lam}": _back(lam) for lam in (0.25, 0.5)})
    return out


def whitening(models: list[Shape]) -> np.ndarray:
    """(J, J) inverse Cholesky factor of the covariance of the fully trusted model samples' slopes."""
    x = np.concatenate([m.sig.slopes[m.sig.valid >= LOCAL.slopes, :LOCAL.slopes] for m in models])
    return np.linalg.inv(np.linalg.cholesky(np.cov(x.astype(np.float64), rowvar=False)))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src")
    p.add_argument("queries")
    p.add_argument("--out", type=Path, default=Path("var/spec"))
    p.add_argument("--start", type=int, default=0)
    p.add_argument("--every", type=int, default=6)
    p.add_argument("--complement", action="store_true", help="the pieces NOT in --start/--every (held out)")
    p.add_argument("--classes", default="", help="these classes only (models and pieces)")
    p.add_argument("--spaces", default="slopes,level0.01,level0.03",
                   help="slopes first: the others' cap is taken at its quantile")
    a = p.parse_args(argv)
    src, qdir = _folder(a.src), _folder(a.queries)
    vocab = Vocabulary.load(VOCABULARY)
    classes = set(a.classes.split(",")) if a.classes else None
    rows = [r for r in read_labelled_folder(src) if classes is None or r.label in classes]
    models = [load(a.out / f"{_key(src, r.path)}.npz", vocab) for r in rows]
    labels = np.array([r.label for r in rows])
    mvec = np.stack([m.vec for m in models])
    msig = [m.sig for m in models]
    marea = np.stack([m.sig.area for m in models]).astype(np.float64)
    qrows = [r for i, r in enumerate(read_labelled_folder(qdir))
             if ((i % a.every == a.start) != a.complement) and (classes is None or r.label in classes)]
    pieces = [load(a.out / f"{_key(qdir, r.path)}.npz", vocab) for r in qrows]
    cands, orders = [], []
    for q in pieces:
        order = np.argsort(np.abs(mvec - q.vec).sum(axis=1), kind="stable")
        coarse = served(pairs(head(q.sig, COARSE_POINTS), msig, order, order), None)
        near = set(order[np.argsort(coarse, kind="stable")[:COARSE_KEEP]].tolist())
        cands.append(order[[j < GLOBAL_KEEP or int(m) in near for j, m in enumerate(order)]])
        orders.append(order)
    among = np.mean([(labels[c] == r.label).any() for c, r in zip(cands, qrows, strict=True)])
    which = f"{'all but ' if a.complement else ''}from {a.start} every {a.every}"
    print(f"{len(pieces)} pieces ({qdir.name}, {which}) against {len(rows)} models; "
          f"class among the candidates {among:.3f}")
    white = whitening(models)
    for space in a.spaces.split(","):
        t0 = time.perf_counter()
        wh = white if space == "whitened" else None
        alpha = float(space[5:]) if space.startswith("level") else 0.0
        tables = [table(q, models, c, wh, alpha) for q, c in zip(pieces, cands, strict=True)]
        nearest = np.concatenate([t.near[np.isfinite(t.near)][::7] for t in tables])
        if space == "slopes":  # the served cap, and its quantile among the nearest distances
            caps, within = {"": CAP}, float((nearest <= CAP).mean())
        else:  # another space: the cap at the same quantile (the tolerance only counts forward)
            caps = {"": float(np.quantile(nearest, within))}
        print(f" {space} ({time.perf_counter() - t0:.0f} s; cap {caps['']:.4g}, tolerance {TOLERANCE})")
        for name, rank in rankings().items():
            ap, nn, wrong = [], [], Counter()
            for r, c, o, t in zip(qrows, cands, orders, tables, strict=True):
                headed = c[np.argsort(rank(t, caps[""], marea[c]), kind="stable")]
                ranked = labels[np.concatenate([headed, o[~np.isin(o, c)]])]
                ap.append(100 * average_precision(ranked, r.label, int((labels == r.label).sum())))
                nn.append(float(ranked[0] == r.label))
                if ranked[0] != r.label:
                    wrong[f"{r.label}>{ranked[0]}"] += 1
            worst = ", ".join(f"{k} {v}" for k, v in wrong.most_common(6)) if name == "served" else ""
            tail = f"   wrong: {worst}" if worst else ""
            print(f"  {name:22s} mAP {np.mean(ap):6.2f}  NN {np.mean(nn):.3f}{tail}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
