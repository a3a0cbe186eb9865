"""Partial queries ranked as POST /search ranks a piece, on a stratified sample of every class.

    python -m benchmarks.partial_served SRC NAME=FOLDER... [--per-class 4] [--split held|pick]
           [--cache-dir .cache/describe] [--workers 1] [--ideas] [--json var/served.json]
           [--level W] [--peer-radius R] [--fit-budget SECONDS]

SRC is the labelled folder of whole models (e.g. `shrec11-simplified`), each NAME=FOLDER a set of pieces
written by benchmarks.partial (labels.csv and partial.csv), e.g. `1cut-60-85=var/p6085`. From each set,
`--per-class` pieces of every class: the first ones of the class, in the folder's order, whose index
in the folder is not 0 mod 6 (`--split held`: never used to pick parameters) or is (`--split pick`).
The models and the chosen pieces are described with the default DescribeParams through the evaluation
cache (resumable: an interrupted run keeps what it described), encoded with the shipped vocabulary
(the fused vector, ranked by L1 as the global index does), and each piece goes through the service's own
code for a piece (app.services.search._scored: app.services.partial's candidates, their score with
the vote, averaged with their nearest fellow candidates', the order), the local signatures and the stored
vectors served from memory instead of the blob store and the database, and
the deadlines lifted (their wall time is printed instead: a loaded machine would otherwise score
fewer candidates and make the figures depend on the load); `--fit-budget` puts the fits' back, to see
what the service's deadline costs on this host. The models that are not candidates follow
in their global order, so mAP reads the whole ranking.

Prints per set: mAP and NN of the global ranking and of the served one, the share of pieces with a
model of their class among the candidates, the wrong first hits by class, the calibration (each piece
against its own whole model: forward, reverse and the scale's kept share against the true kept share),
and the time of the partial stage per piece; for the whole models as queries (each against the others):
how many are taken for pieces, and mAP / NN of the ranking they get. The same candidates are also
ordered by other scores of the same matches (ALTERNATIVES: the mutual share served before the vote, the
distance alone, other vote weights), per piece in --json for paired comparisons; `--ideas` adds
rankings from benchmarks.partial_ideas' float32 tables (a check of the service's numbers, and votes
over other numbers of neighbours). `--level` and `--peer-radius` replace the served weight of the
samples' level difference (app.core.partial_match.LEVEL) and the peers' radius
(app.core.piece_rank.PEER_RADIUS) for the run: how they were picked.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any
from unittest import mock

import numpy as np

from app.core import partial_match, piece_rank
from app.core.partial import LocalSignature
from app.core.partial_match import CAP, PartialMatch, match_many
from app.core.pipeline import LOCAL, DescribeParams, ShapeDescription
from app.core.vocabulary import Vocabulary
from app.datasets.folder import LabelledFile, read_labelled_folder
from app.evaluation.cache import DescriptionCache, Variant, content_sha256, describe_all, load_descriptions
from app.services import partial as partial_mod
from app.services import search as search_mod
from benchmarks.partial_rerank import VOCABULARY, average_precision
from benchmarks.partial_spectra import _folder

PICK_EVERY = 6  # pieces at index 0 mod 6 of a folder were the ones parameters were picked on


def sample(rows: list[LabelledFile], per_class: int, split: str) -> list[int]:
    """Indices into rows: per class, the first `per_class` rows (in folder order) whose index is not
    0 mod PICK_EVERY (split "held") or is (split "pick")."""
    want_pick = split == "pick"
    taken: Counter[str] = Counter()
    out = []
    for i, r in enumerate(rows):
        if (i % PICK_EVERY == 0) == want_pick and taken[r.label] < per_class:
            taken[r.label] += 1
            out.append(i)
    return out


def described(rows: list[LabelledFile], cache_dir: Path, workers: int, label: str) -> list[ShapeDescription]:
    files = [(r.path, content_sha256(r.path)) for r in rows]
    params, cache = DescribeParams(), DescriptionCache(cache_dir)
    describe_all(files, params, cache, workers=workers, label=label)
    return load_descriptions(files, params, cache, Variant())


@dataclass
class Served:
    """The service's ranking of a piece over a collection held in memory.

    vectors : (M, v) fused global vectors; signatures: one local signature (or None) per model."""

    vectors: np.ndarray
    signatures: list[LocalSignature | None]
    seconds: list[float] = field(default_factory=list)  # the partial stage's wall time per piece
    fit_budget_s: float = float("inf")  # the fits' deadline (the service's: partial.FIT_BUDGET_S)
    last: tuple[np.ndarray, list[Any]] = (np.zeros(0, np.int64), [])  # the last piece's candidates, matches

    def global_order(self, vector: np.ndarray, leave_out: int | None = None) -> np.ndarray:
        dist = np.abs(self.vectors - vector).sum(axis=1)
        if leave_out is not None:
            dist[leave_out] = np.inf
        order = np.argsort(dist, kind="stable")
        return order if leave_out is None else order[:-1]

    def rank(self, description: ShapeDescription, order: np.ndarray) -> tuple[np.ndarray, list[Any]]:
        """(the candidates in served order, their hits (forward, reverse, ...)): search._scored on the
        global order, as POST /search calls it for a piece (its COARSE_SCAN nearest read)."""
        wanted = order[: max(partial_mod.COARSE_SCAN, 1)]
        hits = [search_mod.Hit(SimpleNamespace(id=int(j)), 0.0, r + 1)  # type: ignore[arg-type]
                for r, j in enumerate(wanted)]
        sigs = self.signatures
        score = partial_mod.score

        def keep(ctx: Any, query: Any, model_ids: Any, work: Any = None) -> list[Any]:  # the matches, kept
            found = score(ctx, query, model_ids, work)
            self.last = (np.asarray(model_ids, dtype=np.int64), found)
            return found

        # MUTUAL in the service only asks match_many for the mutual share (the score reads the core's
        # weight): the share the ranking served before the vote read, for ALTERNATIVES
        vectors = self.vectors
        with mock.patch.object(partial_mod, "local_of", lambda ctx, model_id: sigs[model_id]), \
                mock.patch.object(partial_mod, "stored_vectors", lambda ctx, vid, ids: vectors[list(ids)]), \
                mock.patch.object(partial_mod, "COARSE_BUDGET_S", float("inf")), \
                mock.patch.object(partial_mod, "SCORE_BUDGET_S", float("inf")), \
                mock.patch.object(partial_mod, "FIT_BUDGET_S", self.fit_budget_s), \
                mock.patch.object(partial_mod, "MUTUAL", 1.0), mock.patch.object(partial_mod, "score", keep):
            t = time.perf_counter()
            out = search_mod._scored(None, description.local, hits,  # type: ignore[arg-type]
                                     partial_mod.RERANK, True, vocabulary_id=0)
            self.seconds.append(time.perf_counter() - t)
        return np.array([h.model.id for h in out], dtype=np.int64), out

    def alternatives(self) -> dict[str, np.ndarray]:
        """The last piece's candidates ordered by each of ALTERNATIVES (as _scored orders: unscored
        last, ties in global order)."""
        ids, found = self.last
        out = {}
        for name, key in ALTERNATIVES.items():
            value = [key(m) if m is not None else float("inf") for m in found]
            out[name] = ids[sorted(range(len(ids)), key=lambda j: (value[j], j))]
        return out


# other scores of the same matches: the own score (served until 2026-12-04, before the peers), the mutual
# share's (served 2026-12-03 to 12-04), the distance alone, the vote at other weights (in CAPs)
ALTERNATIVES: dict[str, Callable[[PartialMatch], float]] = {
    "own score (no peers)": lambda m: m.own,
    "mutual 1 (before)": lambda m: m.distance - CAP * m.mutual,
    "distance alone": lambda m: m.distance,
    "vote x0.25": lambda m: m.distance - 0.25 * CAP * m.vote,
    "vote x1": lambda m: m.distance - CAP * m.vote,
    "mutual 1 + vote x0.5": lambda m: m.distance - CAP * m.mutual - 0.5 * CAP * m.vote,
}


def own_index(mnames: list[str], qname: str) -> int:
    """The collection's index of the model a piece was made from (-1: none of that name)."""
    return mnames.index(qname) if qname in mnames else -1


def full_ranking(head: np.ndarray, order: np.ndarray) -> np.ndarray:
    """The re-ranked head, then every other model in its global order."""
    return np.concatenate([head, order[~np.isin(order, head)]])


def calibration_lines(own: np.ndarray) -> list[str]:
    """own (Q, 4): kept share, forward, reverse, scale of each piece against its own whole model."""
    if len(own) < 2:
        return []
    kept, fwd, rev, scale = own.T
    lines = [f"  own whole: kept {kept.mean():.3f}  forward {fwd.mean():.3f}  reverse {rev.mean():.3f}  "
             f"corr(reverse, kept) {np.corrcoef(kept, rev)[0, 1]:.2f}  |reverse - kept| "
             f"{np.abs(rev - kept).mean():.3f}  |scale - kept| {np.abs(scale - kept).mean():.3f}"]
    for lo in np.arange(0.40, 0.85 - 1e-9, 0.05):
        band = (kept >= lo) & (kept < lo + 0.05)
        if band.any():
            lines.append(f"    kept {lo:.2f}-{lo + 0.05:.2f}: n {band.sum():3d}  "
                         f"forward {fwd[band].mean():.3f}  reverse {rev[band].mean():.3f}  "
                         f"scale {scale[band].mean():.3f}")
    return lines


def run_set(name: str, qdir: Path, served: Served, labels: np.ndarray, mnames: list[str],
            per_class: int, split: str, cache_dir: Path, workers: int, ideas: bool) -> dict[str, Any]:
    rows = read_labelled_folder(qdir)
    chosen = [rows[i] for i in sample(rows, per_class, split)]
    with open(qdir / "partial.csv", newline="") as fh:
        kept = {row["file"]: float(row["kept_fraction"]) for row in csv.DictReader(fh)}
    descs = described(chosen, cache_dir, workers, name)
    vocab = Vocabulary.load(VOCABULARY)
    res: dict[str, list[float]] = {k: [] for k in ("g_ap", "g_nn", "s_ap", "s_nn", "among")}
    wrong: Counter[str] = Counter()
    fits: Counter[str] = Counter()
    own, fwd_same, fwd_other, pieces = [], [], [], 0
    served.seconds.clear()
    extra: dict[str, list[tuple[float, float]]] = {}
    per_piece: list[dict[str, Any]] = []
    for r, d in zip(chosen, descs, strict=True):
        qname = r.path.relative_to(qdir.resolve()).as_posix()
        order = served.global_order(vocab.encode(d).astype(np.float64))
        total = int((labels == r.label).sum())
        res["g_ap"].append(100 * average_precision(labels[order], r.label, total))
        res["g_nn"].append(float(labels[order[0]] == r.label))
        if not partial_mod.is_partial(d.local, None) or d.local is None:
            res["s_ap"].append(res["g_ap"][-1])
            res["s_nn"].append(res["g_nn"][-1])
            continue
        pieces += 1
        cand, hits = served.rank(d, order)
        ranked = labels[full_ranking(cand, order)]
        res["s_ap"].append(100 * average_precision(ranked, r.label, total))
        res["s_nn"].append(float(ranked[0] == r.label))
        res["among"].append(float((labels[cand] == r.label).any()))
        # the fits (app.core.piece_fit): the candidates the piece was shown to lie on, by class
        lying = [int(h.model.id) for h in hits if h.fit is not None and h.fit.lies_on]
        fits["pieces"] += bool(lying)
        fits["source"] += own_index(mnames, qname) in lying
        fits["other class"] += sum(labels[j] != r.label for j in lying)
        fits["same class, not the source"] += sum(labels[j] == r.label and j != own_index(mnames, qname)
                                                  for j in lying)
        if ranked[0] != r.label:
            wrong[f"{r.label} > {ranked[0]}"] += 1
        own_j = mnames.index(qname)
        sig = served.signatures[own_j]
        if sig is not None:
            (m,) = match_many(d.local, [sig], LOCAL)
            own.append((kept[qname], m.forward, m.reverse, m.scale))
        for h in hits:
            if h.forward is not None and int(h.model.id) != own_j:
                (fwd_same if labels[h.model.id] == r.label else fwd_other).append(h.forward)
        src_hit = next((h for h in hits if int(h.model.id) == own_j), None)
        record: dict[str, Any] = {"file": qname, "label": r.label, "kept": kept[qname],
                                  "ap": res["s_ap"][-1], "first": str(ranked[0]),
                                  # where the piece's own source stood: a candidate? fitted? covered?
                                  "source": {"candidate": src_hit is not None,
                                             "fitted": src_hit is not None and src_hit.fit is not None,
                                             "covered": None if src_hit is None or src_hit.fit is None
                                             else round(src_hit.fit.covered, 3)},
                                  # the models of another class the piece was shown to lie on
                                  "lies_on_other": [str(labels[j]) for j in lying if labels[j] != r.label]}
        for key, head in served.alternatives().items():
            alt = labels[full_ranking(head, order)]
            value = (100 * average_precision(alt, r.label, total), float(alt[0] == r.label))
            extra.setdefault(key, []).append(value)
            record[key] = value
        if ideas:
            for key, value in idea_scores(d, served, cand, order, labels, r.label, total).items():
                extra.setdefault(key, []).append(value)
                record[key] = value
        per_piece.append(record)
    out: dict[str, Any] = {
        "set": name, "folder": str(qdir), "pieces": len(chosen), "taken_for_pieces": pieces,
        "global_map": float(np.mean(res["g_ap"])), "global_nn": float(np.mean(res["g_nn"])),
        "served_map": float(np.mean(res["s_ap"])), "served_nn": float(np.mean(res["s_nn"])),
        "class_among_candidates": float(np.mean(res["among"])) if res["among"] else float("nan"),
        "partial_s_median": float(np.median(served.seconds)) if served.seconds else float("nan"),
        "partial_s_max": float(np.max(served.seconds)) if served.seconds else float("nan"),
        "wrong": dict(wrong.most_common()), "own": np.array(own).tolist(),
        "forward_same_class": float(np.mean(fwd_same)) if fwd_same else float("nan"),
        "forward_other_class": float(np.mean(fwd_other)) if fwd_other else float("nan"),
        "fits": dict(fits),
        "ideas": {k: [float(np.mean([a for a, _ in v])), float(np.mean([n for _, n in v]))]
                  for k, v in extra.items()},
        "per_piece": per_piece,
    }
    print_set(out)
    return out


def idea_scores(d: ShapeDescription, served: Served, cand: np.ndarray, order: np.ndarray,
                labels: np.ndarray, label: str, total: int) -> dict[str, tuple[float, float]]:
    """(AP, NN) of benchmarks.partial_ideas' rankings of the same candidates."""
    from benchmarks import partial_ideas as ideas

    assert d.local is not None
    cand = np.sort(cand)  # any fixed order: ties are broken by it
    shapes = {int(j): ideas.Shape(served.vectors[j], sig, np.zeros((len(sig.slopes), 1)))
              for j in cand if (sig := served.signatures[j]) is not None}
    have = np.array([j for j in cand if int(j) in shapes], dtype=np.int64)
    q = ideas.Shape(np.zeros(1), d.local, np.zeros((len(d.local.slopes), 1)))
    models = [shapes[int(j)] for j in have]
    t = ideas.table(q, models, np.arange(len(have)), None, 0.0)
    marea = np.stack([m.sig.area for m in models]).astype(np.float64)
    out = {}
    for name, rank in IDEAS.items():
        head = have[np.argsort(rank(t, CAP, marea), kind="stable")]
        ranked = labels[full_ranking(head, order)]
        out[name] = (100 * average_precision(ranked, label, total), float(ranked[0] == label))
    return out


def _ideas() -> dict[str, Any]:
    """Rankings of the served candidates from the tables (float32): the distance alone, the mutual
    share (served until the vote), the vote (weight in CAPs, top) with and without the mutual share."""
    from benchmarks import partial_ideas as ideas

    return {"distance alone": ideas.r_served, "mutual 1": ideas._mutual(1.0), "mutual 2": ideas._mutual(2.0),
            "vote 10 x0.5": ideas._vote(10, 0.5),
            "mutual 1 + vote 10 x0.25": ideas._mutual_vote(1.0, 10, 0.25),
            "mutual 1 + vote 10 x0.5": ideas._mutual_vote(1.0, 10, 0.5),
            "mutual 1 + vote 10 x1": ideas._mutual_vote(1.0, 10, 1.0),
            "mutual 1 + vote 5 x0.5": ideas._mutual_vote(1.0, 5, 0.5)}


IDEAS = _ideas()


def print_set(s: dict[str, Any]) -> None:
    print(f"{s['set']} ({s['folder']}): {s['pieces']} pieces, {s['taken_for_pieces']} taken for pieces; "
          f"class among the candidates {s['class_among_candidates']:.3f}")
    print(f"  global   mAP {s['global_map']:6.2f}  NN {s['global_nn']:.3f}")
    print(f"  served   mAP {s['served_map']:6.2f}  NN {s['served_nn']:.3f}   partial stage "
          f"{s['partial_s_median']:.2f} s median, {s['partial_s_max']:.2f} s max (one process)")
    f = s.get("fits", {})
    print(f"  fitted: the piece lies on some hit for {f.get('pieces', 0)} pieces; on its source for "
          f"{f.get('source', 0)}, on another model of its class {f.get('same class, not the source', 0)}"
          f" times, on a model of another class {f.get('other class', 0)} times")
    for name, (m, n) in s["ideas"].items():
        print(f"  {name:24s} mAP {m:6.2f}  NN {n:.3f}")
    print(f"  forward of other candidates: same class {s['forward_same_class']:.3f}, other classes "
          f"{s['forward_other_class']:.3f}")
    print("  wrong first hits: " + (", ".join(f"{k} {v}" for k, v in s["wrong"].items()) or "none"))
    for line in calibration_lines(np.array(s["own"])):
        print(line)


def run_whole(served: Served, labels: np.ndarray, descs: list[ShapeDescription]) -> dict[str, Any]:
    """Each whole model against the others: taken for a piece or not, and the ranking it gets."""
    ap, nn, pieces = [], [], 0
    for i, d in enumerate(descs):
        order = served.global_order(served.vectors[i], leave_out=i)
        if partial_mod.is_partial(d.local, None):
            pieces += 1
            order = full_ranking(served.rank(d, order)[0], order)
        total = int((labels == labels[i]).sum()) - 1
        ap.append(100 * average_precision(labels[order], labels[i], total))
        nn.append(float(labels[order[0]] == labels[i]))
    out = {"queries": len(descs), "taken_for_pieces": pieces, "map": float(np.mean(ap)),
           "nn": float(np.mean(nn))}
    print(f"whole models as queries: {len(descs)}, taken for pieces {pieces}; mAP {out['map']:.2f}  "
          f"NN {out['nn']:.3f} (the global fused L1 ranking for every query not taken for a piece)")
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src")
    p.add_argument("sets", nargs="+", help="NAME=FOLDER (a folder written by benchmarks.partial)")
    p.add_argument("--per-class", type=int, default=4)
    p.add_argument("--split", choices=("held", "pick"), default="held")
    p.add_argument("--cache-dir", type=Path, default=Path(".cache/describe"))
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--ideas", action="store_true", help="also the mutual + vote rankings (partial_ideas)")
    p.add_argument("--json", type=Path, default=None, help="write every figure here")
    p.add_argument("--level", type=float, default=None,
                   help=f"the level's weight in a sample pair's distance (served: {partial_match.LEVEL})")
    p.add_argument("--peer-radius", type=float, default=None,
                   help=f"only candidates this near are peers (served: {piece_rank.PEER_RADIUS})")
    p.add_argument("--fit-budget", type=float, default=float("inf"),
                   help=f"the fits' deadline in seconds (default: none; served: {partial_mod.FIT_BUDGET_S})")
    a = p.parse_args(argv)
    if a.level is not None:  # match_many reads the module's weight at each call
        partial_match.LEVEL = a.level
    if a.peer_radius is not None:  # with_peers reads piece_rank's name at each call
        piece_rank.PEER_RADIUS = a.peer_radius
    src = _folder(a.src)
    sets = [(n, _folder(f)) for n, f in (s.split("=", 1) for s in a.sets)]
    rows = read_labelled_folder(src)
    descs = described(rows, a.cache_dir, a.workers, src.name)
    vocab = Vocabulary.load(VOCABULARY)
    served = Served(np.stack([vocab.encode(d) for d in descs]).astype(np.float64), [d.local for d in descs],
                    fit_budget_s=a.fit_budget)
    labels = np.array([r.label for r in rows])
    mnames = [r.path.relative_to(src.resolve()).as_posix() for r in rows]
    print(f"{len(rows)} models ({src.name}), {len(set(labels))} classes; {a.per_class} pieces a class a set, "
          f"split {a.split}; candidates: global {partial_mod.GLOBAL_KEEP} + coarse "
          f"{partial_mod.COARSE_KEEP}; level weight {partial_match.LEVEL}, "
          f"peer radius {piece_rank.PEER_RADIUS}")
    report: dict[str, Any] = {"whole": run_whole(served, labels, descs), "sets": []}
    for name, qdir in sets:
        report["sets"].append(run_set(name, qdir, served, labels, mnames, a.per_class, a.split,
                                      a.cache_dir, a.workers, a.ideas))
        if a.json:  # after every set: a long run interrupted keeps what it measured
            a.json.parent.mkdir(parents=True, exist_ok=True)
            a.json.write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
