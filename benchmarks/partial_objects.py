"""A query that is one object of a multi-object file (issue 33): is the file found?

    python -m benchmarks.partial_objects SRC [--per-class 2] [--out var/plates] [--max-objects 8]
           [--cache-dir .cache/describe] [--workers 2]

For the first `--per-class` models of each class of the labelled folder SRC outside the picking split
(index not 0 mod 6), two multi-object files are built as benchmarks.variants_detect_kinds builds its
plates: a plate of 2-6 copies of the model, and a plate holding it among 1-3 models of other classes
brought to its size (seeded per model). The models and the plates are described through the
evaluation cache and encoded with the shipped vocabulary (the fused vector the global index ranks by
L1); each base model is then the query, its own stored copy left out, and the rank of each of its two
plates is printed for two indexes:
- **whole rows** (what the service indexes): one row a model;
- **whole + object rows** (not served): each of a multi-object file's objects
  (app.core.variants.surface.objects, the `--max-objects` largest) is described as a mesh of its own
  and indexed as a row of the file too; a model's distance is the least over its rows.
It also prints SRC's whole-query mAP against SRC plus the plates under both indexes, the plates left
out of the scoring (a plate is not a class-mate), so that what object rows cost other queries shows.
"""

from __future__ import annotations

import argparse
import csv
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.mesh import load_mesh
from app.core.variants.surface import objects
from app.core.vocabulary import Vocabulary
from app.datasets.folder import LabelledFile, read_labelled_folder
from benchmarks.partial_served import PICK_EVERY, VOCABULARY, _folder, described
from benchmarks.variants import _obj_text
from benchmarks.variants_detect_kinds import plate, plate_member

MAX_OBJECTS = 8  # objects described per file, the largest (by vertices) first


@dataclass(frozen=True)
class Plate:
    file: str  # its name in the output folder
    label: str  # its base model's class
    base: int  # the base model's index in SRC's rows
    kind: str  # "copies" | "member"
    objects: int  # models placed on it


def bases(rows: list[LabelledFile], per_class: int) -> list[int]:
    """The first `per_class` models of each class, in folder order, outside the picking split."""
    taken: dict[str, list[int]] = {}
    for i, r in enumerate(rows):
        if i % PICK_EVERY and len(taken.setdefault(r.label, [])) < per_class:
            taken[r.label].append(i)
    return [i for group in taken.values() for i in group]


def build_plates(rows: list[LabelledFile], chosen: list[int], out: Path, seed: int = 7) -> list[Plate]:
    """Two plates of each chosen model written to `out` (OBJ, labels.csv); seeded by (seed, index)."""
    out.mkdir(parents=True, exist_ok=True)
    made = []
    for b in chosen:
        rng = np.random.default_rng([seed, b])
        base = load_mesh(rows[b].path)
        copies = int(rng.integers(2, 7))
        pool = [j for j in range(len(rows)) if rows[j].label != rows[b].label]
        count = min(int(rng.integers(1, 4)), len(pool))
        others = [load_mesh(rows[int(j)].path) for j in rng.choice(pool, count, replace=False)]
        for kind, mesh, count in (("copies", plate([base] * copies, rng), copies),
                                  ("member", plate_member(base, others, rng), len(others) + 1)):
            name = f"{kind}_{b}.obj"
            (out / name).write_text(_obj_text(mesh))
            made.append(Plate(name, rows[b].label, b, kind, count))
    _write_labels(out, [(p.file, p.label) for p in made])
    return made


def split_objects(plates: list[LabelledFile], out: Path, max_objects: int = MAX_OBJECTS) -> list[int]:
    """Each plate's objects (the `max_objects` largest) written to `out` as meshes of their own, in
    plate order; the index of the plate each object row belongs to."""
    out.mkdir(parents=True, exist_ok=True)
    owner, names = [], []
    for j, r in enumerate(plates):
        parts = sorted(objects(load_mesh(r.path)), key=lambda m: -m.n_vertices)[:max_objects]
        for k, part in enumerate(parts):
            name = f"{r.path.stem}__o{k}.obj"
            (out / name).write_text(_obj_text(part))
            owner.append(j)
            names.append((name, r.label))
    _write_labels(out, names)
    return owner


def least_over_rows(query: np.ndarray, whole: np.ndarray, parts: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """(N,) each model's L1 distance to `query` (v,): the least over its whole row (whole (N, v)) and its
    object rows (parts (P, v), owner (P,) the model of each)."""
    out = np.abs(whole - query).sum(axis=1)
    if len(parts):
        np.minimum.at(out, owner, np.abs(parts - query).sum(axis=1))
    return out


def mean_average_precision(whole: np.ndarray, parts: np.ndarray, owner: np.ndarray, labels: np.ndarray,
                           scored: int) -> float:
    """mAP of the first `scored` models as queries (each leaving itself out) over the first `scored`
    models: the rows past them (plates) are ranked but never relevant nor counted."""
    aps = []
    for i in range(scored):
        d = least_over_rows(whole[i], whole, parts, owner)
        d[i] = np.inf
        order = np.argsort(d, kind="stable")[:-1]
        order = order[order < scored]
        relevant = labels[order] == labels[i]
        if not relevant.any():
            continue
        hits = np.cumsum(relevant)
        aps.append(float(np.mean(hits[relevant] / (np.flatnonzero(relevant) + 1))))
    return float(np.mean(aps))


def _write_labels(out: Path, rows: list[tuple[str, str]]) -> None:
    with open(out / "labels.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["file", "class"])
        w.writerows(rows)


def _mesh_rows(folder: Path, names: list[str]) -> list[LabelledFile]:
    """The labelled rows of `folder` in the order of `names`."""
    found = {r.path.name: r for r in read_labelled_folder(folder)}
    return [found[n] for n in names]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src")
    p.add_argument("--per-class", type=int, default=2)
    p.add_argument("--out", type=Path, default=Path("var/plates"))
    p.add_argument("--max-objects", type=int, default=MAX_OBJECTS)
    p.add_argument("--cache-dir", type=Path, default=Path(".cache/describe"))
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args(argv)
    src = _folder(a.src)
    rows = read_labelled_folder(src)
    t = time.perf_counter()
    plates = build_plates(rows, bases(rows, a.per_class), a.out)
    plate_rows = _mesh_rows(a.out, [q.file for q in plates])
    owner = np.array(split_objects(plate_rows, a.out / "objects", a.max_objects), dtype=np.int64)
    print(f"{len(plates)} plates of {len(plates) // 2} models, {len(owner)} objects, built in "
          f"{time.perf_counter() - t:.0f} s")
    object_rows = read_labelled_folder(a.out / "objects")
    by_name = {r.path.name: r for r in object_rows}
    object_rows = [by_name[f"{r.path.stem}__o{k}.obj"] for r, k in _object_order(plate_rows, owner)]
    vocab = Vocabulary.load(VOCABULARY)
    encode = lambda descs: np.stack([vocab.encode(d) for d in descs]).astype(np.float64)  # noqa: E731
    whole = encode(described(rows, a.cache_dir, a.workers, src.name)
                   + described(plate_rows, a.cache_dir, a.workers, "plates"))
    t = time.perf_counter()
    parts = encode(described(object_rows, a.cache_dir, a.workers, "objects"))
    print(f"objects described and encoded in {time.perf_counter() - t:.0f} s ({len(parts)} objects)")
    n = len(rows)
    owner_rows = owner + n
    ranks: dict[tuple[str, str], list[int]] = {}
    for j, q in enumerate(plates):
        for index, (rows_p, owner_p) in (("whole rows", (parts[:0], owner_rows[:0])),
                                         ("whole + object rows", (parts, owner_rows))):
            d = least_over_rows(whole[q.base], whole, rows_p, owner_p)
            d[q.base] = np.inf  # the query's own stored copy
            ranks.setdefault((q.kind, index), []).append(int(np.sum(d < d[n + j])) + 1)
    print(f"{'plate':8s} {'index':20s} {'n':>4s} {'first':>6s} {'top 10':>6s} {'median rank':>11s}")
    for (kind, index), v in sorted(ranks.items()):
        r = np.array(v)
        print(f"{kind:8s} {index:20s} {len(r):4d} {np.mean(r == 1):6.3f} {np.mean(r <= 10):6.3f} {np.median(r):11.0f}")
    labels = np.array([r.label for r in rows] + [q.label for q in plates])
    for index, (rows_p, owner_p) in (("whole rows", (parts[:0], owner_rows[:0])),
                                     ("whole + object rows", (parts, owner_rows))):
        print(f"{src.name} whole queries, {index}: mAP "
              f"{100 * mean_average_precision(whole, rows_p, owner_p, labels, n):.2f}")
    return 0


def _object_order(plate_rows: list[LabelledFile], owner: np.ndarray) -> list[tuple[LabelledFile, int]]:
    """(plate row, object number) of each object row, in split_objects' order."""
    out, seen = [], {}
    for j in owner:
        k = seen.get(int(j), 0)
        seen[int(j)] = k + 1
        out.append((plate_rows[int(j)], k))
    return out


__all__ = ["bases", "build_plates", "least_over_rows", "mean_average_precision", "split_objects"]


if __name__ == "__main__":
    raise SystemExit(main())
