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
It also prints SRC's whole-query NN and mAP (app.core.metrics) over SRC and the plates under both
indexes, a plate relevant to a query when it holds a model of the query's class, and how many
queries' first hit is a plate: what object rows change for queries that are not looking for a plate.
"""

from __future__ import annotations

import argparse
import csv
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.mesh import load_mesh
from app.core.metrics import relevance_scores
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
    classes: tuple[str, ...]  # the classes of the models placed on it


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
        chosen_others = [int(j) for j in rng.choice(pool, count, replace=False)]
        others = [load_mesh(rows[j].path) for j in chosen_others]
        member_classes = (rows[b].label, *(rows[j].label for j in chosen_others))
        for kind, mesh, held in (("copies", plate([base] * copies, rng), (rows[b].label,) * copies),
                                 ("member", plate_member(base, others, rng), member_classes)):
            name = f"{kind}_{b}.obj"
            (out / name).write_text(_obj_text(mesh))
            made.append(Plate(name, rows[b].label, b, kind, len(held), tuple(sorted(set(held)))))
    _write_labels(out, [(p.file, p.label) for p in made])
    return made


def split_objects(plates: list[LabelledFile], out: Path,
                  max_objects: int = MAX_OBJECTS) -> tuple[list[int], list[str]]:
    """Each plate's objects (the `max_objects` largest) written to `out` as meshes of their own, in
    plate order: the index of the plate each object row belongs to, and its file name."""
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
    return owner, [name for name, _ in names]


def least_over_rows(query: np.ndarray, whole: np.ndarray, parts: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """(N,) each model's L1 distance to `query` (v,): the least over its whole row (whole (N, v)) and its
    object rows (parts (P, v), owner (P,) the model of each)."""
    out = np.abs(whole - query).sum(axis=1)
    if len(parts):
        np.minimum.at(out, owner, np.abs(parts - query).sum(axis=1))
    return out


def whole_query_scores(whole: np.ndarray, parts: np.ndarray, owner: np.ndarray, labels: np.ndarray,
                       holds: list[tuple[str, ...]]) -> dict[str, float]:
    """The first len(labels) models as queries (each leaving itself out) over every row's model:
    app.core.metrics' NN and mAP, a model relevant when of the query's class and a plate (model
    len(labels) + j) when holds[j] has it; and "plate first", the share of queries whose first hit is
    a plate. whole (N, v), parts (P, v), owner (P,) as least_over_rows."""
    n = len(labels)
    relevant, plate_first = [], []
    for i in range(n):
        d = least_over_rows(whole[i], whole, parts, owner)
        d[i] = np.inf
        order = np.argsort(d, kind="stable")[:-1]
        relevant.append([labels[j] == labels[i] if j < n else labels[i] in holds[j - n] for j in order])
        plate_first.append(order[0] >= n)
    scores = relevance_scores(np.array(relevant))
    return {"NN": float(scores["NN"].mean()), "mAP": float(scores["mAP"].mean()),
            "plate first": float(np.mean(plate_first))}


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
    owned, names = split_objects(plate_rows, a.out / "objects", a.max_objects)
    owner = np.array(owned, dtype=np.int64)
    print(f"{len(plates)} plates of {len(plates) // 2} models, {len(owner)} objects, built in "
          f"{time.perf_counter() - t:.0f} s")
    object_rows = _mesh_rows(a.out / "objects", names)
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
        print(f"{kind:8s} {index:20s} {len(r):4d} {np.mean(r == 1):6.3f} {np.mean(r <= 10):6.3f} "
              f"{np.median(r):11.0f}")
    labels = np.array([r.label for r in rows])
    for index, (rows_p, owner_p) in (("whole rows", (parts[:0], owner_rows[:0])),
                                     ("whole + object rows", (parts, owner_rows))):
        got = whole_query_scores(whole, rows_p, owner_p, labels, [q.classes for q in plates])
        print(f"{src.name} whole queries over the models and the plates (a plate relevant when it holds "
              f"the query's class), {index}: NN {got['NN']:.3f}  mAP {100 * got['mAP']:.2f}  "
              f"first hit a plate {got['plate first']:.3f}")
    return 0


__all__ = ["bases", "build_plates", "least_over_rows", "split_objects", "whole_query_scores"]


if __name__ == "__main__":
    raise SystemExit(main())
