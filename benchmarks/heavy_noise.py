"""Heavy noise on closed shapes: what the rule on folded inputs does, from descriptions cached before it.

    python -m benchmarks.heavy_noise --cache .cache/describe/<key> var/kinchars-s1@0.01 var/fine@0.01 ...

Each column is a labelled folder described in the cache, with `@NSR` for its noisy queries against the
clean collection (as benchmarks.fusion_offline reads them). Per query, from its mesh as described:

- fold share (app.core.roughness.fold_share): the share of interior edges whose two faces' normals are
  more than 120 degrees apart; heavy noise folds the surface (docs/results.md: 0.45-0.51 at NSR 1e-2
  at full resolution, at most 0.06 on clean meshes of 100 vertices or more);
- whether the mesh is watertight (every edge on exactly two faces), and its canonical rim (stored).

A query is *hit* when it is folded (FOLDED or more), its mesh is watertight and its canonical rim is at
least OPENED: the cleaning opened a closed input. Printed: the ranking served before the rule (the
fusion re-rank, a query with a rim as a piece) and the same with every hit query taken as closed and
noisy with a Shape-DNA weight of at least W, for a few W; with --any-folded, without the "opened"
condition. From 2026-12-04 the service described such a query with rim 0 (a rule on the fold share);
the rim measured before smoothing, over free edges only, reads none on them (it fired on 1 of 362
noisy closed queries, at rim 0.014: docs/partial.md, "Punctures are not rims"), so the rule is gone and
descriptions made since then have no hit queries: --any-folded tries the weights on them.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from app.core import fusion
from app.core.roughness import FOLDED, fold_share, watertight
from app.core.vocabulary import Vocabulary
from app.evaluation import adaptive, sets
from app.evaluation.cache import Variant, load_variant
from benchmarks.fusion_offline import Column, _masked, load_column, scores

OPENED = 0.05  # canonical rim from which a watertight input counts as opened by the cleaning


def hits(col: Column, spec: str, any_folded: bool) -> np.ndarray:
    """(q,) bool: the column's queries the rule would take as closed and noisy."""
    folder_spec, _, noise = spec.partition("@")
    folder = sets.read_folder(folder_spec.split("~")[-1])
    out = []
    for (path, sha), rim in zip(folder.files, col.query_rims, strict=True):
        mesh = load_variant(str(path), sha, Variant(float(noise or 0), 0))
        folded = fold_share(mesh) >= FOLDED
        out.append(folded if any_folded else folded and watertight(mesh) and rim >= OPENED)
    return np.array(out, dtype=bool)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("columns", nargs="+", help="FOLDER[@NSR], described in the cache")
    ap.add_argument("--cache", type=Path, required=True, help="a description cache directory")
    ap.add_argument("--vocabulary", default="app/data/vocabulary/default")
    ap.add_argument("--weights", default="4,8,16", help="Shape-DNA weights W to try")
    ap.add_argument("--any-folded", action="store_true", help="the rule without the 'opened' condition")
    args = ap.parse_args(argv)
    vocab = Vocabulary.load(args.vocabulary)
    if vocab.fusion is None:
        raise SystemExit(f"{args.vocabulary} has no fusion scales")
    base = fusion.AdaptiveRule()
    for spec in args.columns:
        col = load_column(spec, args.cache, vocab)
        if col is None:
            continue
        hit = hits(col, spec, args.any_folded)
        closed_locals = [replace(q, rim=0.0) if h and q is not None else q
                         for q, h in zip(col.query_locals, hit, strict=True)]

        def ranks(rule: fusion.AdaptiveRule, rims: np.ndarray, noises: np.ndarray, locals_: list,
                  col: Column = col) -> np.ndarray:
            return adaptive.ranks(col.queries, col.db, col.left_out, vocab.size, vocab.fusion.weight, rule,
                                  adaptive.CANDIDATES, rims, noises, locals_, col.db_locals)

        now = ranks(base, col.query_rims, col.query_noises, col.query_locals)
        line = [f"{spec}: {int(hit.sum())} of {len(hit)} hit",
                f"served {scores(_masked(now, col), col)[0]:.2f}"]
        for w in (float(x) for x in args.weights.split(",")):
            # the hit queries closed and noisy at weight w; every other query exactly as served
            ruled = ranks(replace(base, noisy_weight=w), np.where(hit, 0.0, col.query_rims),
                          np.where(hit, -1.0, col.query_noises), closed_locals)
            mAP = scores(_masked(np.where(hit[:, None], ruled, now), col), col)[0]
            line.append(f"W {w:g}: {mAP:.2f}")
        print("  ".join(line), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
