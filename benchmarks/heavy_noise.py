"""Heavy noise on closed shapes: would a rule on folded inputs serve them? (measured, not built)

    python -m benchmarks.heavy_noise --cache .cache/describe/<key> var/kinchars-s1@0.01 var/fine@0.01 ...

Each column is a labelled folder described in the cache, with `@NSR` for its noisy queries against the
clean collection (as benchmarks.fusion_offline reads them). Per query, from its mesh as described:

- fold share: the share of interior edges whose two faces' normals are more than FOLD_ANGLE apart;
  heavy noise (larger than an edge) folds the surface (docs/results.md: 0.45-0.51 at NSR 1e-2 at full
  resolution, at most 0.06 on clean meshes of MIN_VERTICES or more);
- whether the mesh is watertight (every edge on exactly two faces), and its canonical rim (stored).

A query is *hit* when it is folded (FOLDED or more), its mesh is watertight and its canonical rim is at
least OPENED: the cleaning opened a closed input. Printed: the served ranking (the fusion re-rank, a
query with a rim as a piece) and the same with every hit query taken as closed and noisy with a
Shape-DNA weight of at least W, for a few W; with --any-folded, the rule without the "opened" condition.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from app.core import fusion
from app.core.meshdata import Mesh
from app.core.vocabulary import Vocabulary
from app.evaluation import adaptive, sets
from app.evaluation.cache import Variant, load_variant
from benchmarks.fusion_offline import Column, _masked, load_column, scores

FOLD_ANGLE = 2 * np.pi / 3  # normals more than 120 degrees apart: the surface folds back on itself
FOLDED = 0.3  # fold share from which a mesh counts as heavily noisy
OPENED = 0.05  # canonical rim from which a watertight input counts as opened by the cleaning
MIN_VERTICES = 100  # fewer: every vertex is a corner (a tetrahedron's edges read 0.33), not measured


def edge_faces(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's edges as sorted vertex pairs (e, 2) and how many faces use each (e,)."""
    pairs = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges, counts = np.unique(pairs, axis=0, return_counts=True)
    return edges, counts


def watertight(mesh: Mesh) -> bool:
    """Every edge on exactly two faces."""
    return bool(len(mesh.faces)) and bool((edge_faces(mesh.faces)[1] == 2).all())


def fold_share(mesh: Mesh) -> float:
    """Share of the edges with exactly two faces whose normals are more than FOLD_ANGLE apart; NaN
    under MIN_VERTICES vertices or with no such edge."""
    if mesh.n_vertices < MIN_VERTICES or not len(mesh.faces):
        return float("nan")
    tri = mesh.vertices[mesh.faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    pairs = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)  # (3f, 2), face = row // 3
    _, inverse, counts = np.unique(pairs, axis=0, return_inverse=True, return_counts=True)
    order = np.argsort(inverse, kind="stable")
    inner = counts[inverse[order]] == 2  # the two rows of each interior edge are together in `order`
    rows = order[inner].reshape(-1, 2)
    if not len(rows):
        return float("nan")
    cos = (normals[rows[:, 0] // 3] * normals[rows[:, 1] // 3]).sum(axis=1)
    return float((cos < np.cos(FOLD_ANGLE)).mean())


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
