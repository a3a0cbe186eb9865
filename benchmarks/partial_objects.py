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

`--served` then measures the same through the service's own code: a data directory with the shipped
vocabulary, SRC's models and the plates stored as ingestion stores them (the cached descriptions of the
wholes; each plate's object rows made by app.services.object_rows.describe_objects, timed), and every
model of SRC asked for its neighbours through app.services.search.similar (the served ranking: fused
index, object rows merged, the query-adaptive re-rank; k = 100, the rest of the ranking in the index's
order over whole and object rows). It prints the plates' ranks and the whole-query scores as above,
for the service with its object rows and with them withheld (SHAPEBAG_OBJECT_ROWS=0).
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
    p.add_argument("--served", action="store_true", help="also measure through the service's own code")
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
    if a.served:
        served(rows, plates, plate_rows, a.cache_dir, a.workers)
    return 0


def served(rows: list[LabelledFile], plates: list[Plate], plate_rows: list[LabelledFile], cache_dir: Path,
           workers: int) -> None:
    """The module docstring's `--served` measurement."""
    import tempfile

    from app.config import Settings
    from app.core.pipeline import DescribeParams, describe
    from app.services import object_rows, search, vocabularies
    from app.services.context import open_context
    from app.services.live_index import LiveIndex
    from benchmarks.partial_scale import _encoder, store_real

    descs = described(rows, cache_dir, workers, "models")
    descs += described(plate_rows, cache_dir, workers, "plates")
    with tempfile.TemporaryDirectory(prefix="partial-objects-") as tmp:
        ctx = open_context(Settings(data_dir=Path(tmp) / "data", dev_mode=True))
        vocabularies.ensure_default(ctx)
        params = ctx.settings.describe.params()
        assert params == DescribeParams(), "the cached descriptions are the service's default describe"
        ids = store_real(ctx, [*rows, *plate_rows], descs)
        vid, encode = _encoder(ctx)
        t, found = time.perf_counter(), []
        for r in plate_rows:
            found.append(object_rows.describe_objects(load_mesh(r.path), params, ctx.settings.object_rows))
        seconds = time.perf_counter() - t
        t = time.perf_counter()
        for r in plate_rows:  # the baseline: what the plates' ingest describes without object rows
            describe(load_mesh(r.path), params)
        whole_s = time.perf_counter() - t
        print(f"object rows: {sum(len(f) for f in found)} for {len(plate_rows)} plates "
              f"({sum(o.row.copies for f in found for o in f)} objects), described in {seconds:.1f} s, "
              f"the plates' whole describes {whole_s:.1f} s (ratio {seconds / whole_s:.2f})")
        whole = np.stack([encode(d) for d in descs]).astype(np.float64)
        part_vectors, owner = [], []
        with ctx.db.write() as conn:
            for j, (mid, objs) in enumerate(zip(ids[len(rows):], found, strict=True)):
                vectors = [encode(o.description) for o in objs]
                object_rows.store(conn, mid, objs, vid, vectors)
                part_vectors += vectors
                owner += [len(rows) + j] * len(objs)
        parts = np.array(part_vectors, np.float64).reshape(len(owner), whole.shape[1])
        n = len(rows)
        labels = np.array([r.label for r in rows])
        holds = [q.classes for q in plates]
        for setting, rows_on in (("with object rows (served)", True), ("object rows withheld", False)):
            live = LiveIndex(ctx)
            live.refresh()
            if not rows_on:
                live.require().objects = None
            ranked, took = [], []
            for i in range(n):
                t = time.perf_counter()
                hits = search.similar(ctx, live, ids[i], k=search.MAX_K).hits
                took.append(time.perf_counter() - t)
                ranked.append(([ids.index(h.model.id) for h in hits], [h.part for h in hits]))
            ranks: dict[str, list[int]] = {}
            for j, q in enumerate(plates):
                order = ranked[q.base][0]
                ranks.setdefault(q.kind, []).append(order.index(n + j) + 1 if n + j in order else 10**6)
            for kind, v in sorted(ranks.items()):
                r = np.array(v)
                print(f"served, {setting}: plate of {kind:7s} n {len(r)}  first {np.mean(r == 1):.3f}  "
                      f"top 10 {np.mean(r <= 10):.3f}  in top 100 {np.mean(r <= 100):.3f}")
            relevant, plate_first, matched = [], [], 0
            held = (parts, np.array(owner, np.int64)) if rows_on else (parts[:0], np.zeros(0, np.int64))
            for i, (order, matched_parts) in enumerate(ranked):
                d = least_over_rows(whole[i], whole, *held)
                served_now = set(order) | {i}
                rest = [int(j) for j in np.argsort(d, kind="stable") if int(j) not in served_now]
                full = order + rest  # beyond the 100 served: the index's order over the rows
                relevant.append([labels[j] == labels[i] if j < n else labels[i] in holds[j - n]
                                 for j in full])
                plate_first.append(order[0] >= n)
                matched += sum(1 for j, part in zip(order, matched_parts, strict=True) if j >= n and part > 0)
            scores = relevance_scores(np.array(relevant))
            print(f"served, {setting}: whole queries NN {scores['NN'].mean():.3f}  mAP "
                  f"{100 * scores['mAP'].mean():.2f}  first hit a plate {np.mean(plate_first):.3f}  "
                  f"plate hits through an object {matched}  similar() p50 {1000 * np.median(took):.0f} ms")


__all__ = ["bases", "build_plates", "least_over_rows", "split_objects", "whole_query_scores"]


if __name__ == "__main__":
    raise SystemExit(main())
