"""Where the variant step's CPU goes, stage by stage, over variants_ingest's sequence of realworld meshes.

    python -m benchmarks.variants_stages [--limit 16] [--max-vertices 20000]

The core of services.variants.detect without the database: each mesh is prepared and fingerprinted
(whole and objects), its candidates are looked up among the meshes before it, and relate() runs on
each; the stages of relate.py are timed in this process's CPU seconds (BLAS pinned to one thread) and
counted: how many pairs reach the gate, the fits, the quick, middle and full distances.
"""

from __future__ import annotations

import argparse
import importlib
import time
from collections import defaultdict
from collections.abc import Callable
from types import ModuleType

import numpy as np

from app.core.mesh import InvalidMeshError, load_mesh
from app.core.variants import Prepared
from app.core.variants.collection import fingerprints, shortlist
from app.core.variants.index import FingerprintIndex
from app.datasets import locate
from app.worker.processes import pin_threads
from benchmarks.common import machine, table
from benchmarks.variants_ingest import corpus


class Stages:
    """CPU seconds and calls per stage; wrap() replaces a module's function by a timed one."""

    def __init__(self) -> None:
        self.seconds: defaultdict[str, float] = defaultdict(float)
        self.calls: defaultdict[str, int] = defaultdict(int)

    def wrap(self, module: ModuleType, name: str, label: Callable[[tuple, dict], str | None] | str) -> None:
        """`label`: the stage's name, or a function of the call's arguments giving it (None: not timed,
        the call is part of a stage timed around it)."""
        real = getattr(module, name)

        def timed(*args: object, **kwargs: object) -> object:
            key = label(args, kwargs) if callable(label) else label
            if key is None:
                return real(*args, **kwargs)
            start = time.process_time()
            try:
                return real(*args, **kwargs)
            finally:
                self.seconds[key] += time.process_time() - start
                self.calls[key] += 1

        setattr(module, name, timed)

    def add(self, key: str, seconds: float, calls: int = 1) -> None:
        self.seconds[key] += seconds
        self.calls[key] += calls

    def rows(self) -> list[dict]:
        return [{"stage": k, "CPU s": self.seconds[k], "calls": self.calls[k]}
                for k in sorted(self.seconds, key=lambda k: -self.seconds[k])]


def instrument(stages: Stages) -> ModuleType:
    """Time relate.py's stages (the module's own names, so relate() calls the timed ones)."""
    r = importlib.import_module("app.core.variants.relate")
    stages.wrap(r, "may_relate", "gate (fingerprint gap, resolutions)")
    stages.wrap(r, "verify", "verify (whole or object pair)")
    stages.wrap(r, "_parts_in", "objects (_parts_in, its verifications included)")
    stages.wrap(r, "_exact", "same-triangles test")
    stages.wrap(r, "_hypotheses", "hypotheses (screen + coarse ICP)")
    quick = r.QUICK_ROUNDS  # _polished(a, b, points, rough, rounds): the quick polish runs QUICK_ROUNDS
    stages.wrap(r, "_polished", lambda a, k: "quick polish (256 points)" if len(a) > 4 and a[4] == quick
                else None)  # the fine one is inside _fine_fit
    stages.wrap(r, "_fine_fit", "fine polish (1,024 points)")
    stages.wrap(r, "_evidence", lambda a, k: {r.QUICK_POINTS: "quick distances (256 samples)",
                                              r.MIDDLE_POINTS: "middle distances (512 samples)"}.get(
                                                  k.get("points"), "full distances (2,048 samples)"))
    return r


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--limit", type=int, default=16)
    ap.add_argument("--max-vertices", type=int, default=20_000)
    args = ap.parse_args(argv)
    pin_threads()
    try:
        root = locate.require("realworld")
    except locate.DatasetMissing as exc:
        print(f"variants_stages: {exc}")
        return 2
    stages = Stages()
    r = instrument(stages)
    index, stored = FingerprintIndex(), []
    for path in corpus(root, args.limit, args.max_vertices):
        try:
            mesh = load_mesh(path)
        except (InvalidMeshError, ValueError):
            continue
        start = time.process_time()
        p = Prepared(mesh)
        vectors = fingerprints(p)
        stages.add("fingerprints of the new mesh", time.process_time() - start)
        start = time.process_time()
        found = shortlist(index, vectors)
        stages.add("lookup (candidates)", time.process_time() - start, len(found))
        for j in found:
            start = time.process_time()
            r.relate(p, stored[j])
            stages.add("relate, all of it", time.process_time() - start)
        index.add(np.full(len(vectors), len(stored)), vectors)
        stored.append(p)
    print(table(stages.rows(), title=f"variant step over {len(stored)} realworld ingests, CPU seconds"))
    print(machine())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
