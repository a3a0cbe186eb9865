"""What a describe setting costs on the realworld corpus, paired in one process.

    python -m benchmarks.describe_cost antialias=0            # the defaults against antialias 0
    python -m benchmarks.describe_cost smoothing=0 --files '*stl*'

Each readable corpus entry is loaded once (as an upload), then described with the defaults and with
the given override, in alternating order, timed by CPU time (one BLAS thread), so that the ratio does
not depend on what else the machine runs. Prints the totals, the ratio of the totals (defaults over
the override) and the median per-file ratio. Entries the upload path refuses are skipped.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace

os.environ.setdefault("OMP_NUM_THREADS", "1")  # before numpy: CPU time of one thread is what is compared
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from app.core.meshdata import Mesh  # noqa: E402
from app.core.pipeline import DescribeParams  # noqa: E402
from benchmarks.realworld import CORPUS, corpus_entries, upload_of  # noqa: E402


def parse_override(text: str) -> dict:
    """'antialias=0' -> {'antialias': 0.0}, typed by the DescribeParams field's default."""
    name, _, value = text.partition("=")
    default = getattr(DescribeParams(), name, None)
    if default is None or not value:
        raise SystemExit(f"describe_cost: {text!r} is not NAME=VALUE of a DescribeParams field")
    return {name: type(default)(value) if not isinstance(default, bool) else value == "true"}


def cpu_seconds(mesh: Mesh, params: DescribeParams, stages: dict[str, float] | None = None) -> float:
    """CPU seconds of describe(mesh, params); its stages' wall seconds are added to `stages`."""
    from app.core.pipeline import describe

    t = time.process_time()
    description = describe(mesh, params)
    spent = time.process_time() - t
    if stages is not None:
        for stage, seconds in description.seconds.items():
            stages[stage] = stages.get(stage, 0.0) + seconds
    return spent


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("override", help="NAME=VALUE of DescribeParams, the baseline against the defaults")
    ap.add_argument("--files", action="append", help="glob on the corpus entry names (repeatable)")
    args = ap.parse_args(argv)
    from app.config import Settings
    from app.core.mesh import InvalidMeshError
    from app.services.mesh_policy import load_upload

    defaults = DescribeParams()
    other = replace(defaults, **parse_override(args.override))
    max_vertices = Settings.model_fields["max_vertices"].default
    rows = []
    stages: dict[str, float] = {}  # the defaults' stages, wall seconds summed over the entries
    for i, entry in enumerate(corpus_entries(CORPUS, args.files or ["*"])):
        data, name = upload_of(entry)
        try:
            mesh = load_upload(data, name, max_vertices)
            order = (defaults, other) if i % 2 == 0 else (other, defaults)
            pair = [cpu_seconds(mesh, p, stages if p is defaults else None) for p in order]
        except (InvalidMeshError, ValueError):
            continue
        ours, theirs = pair if i % 2 == 0 else pair[::-1]
        rows.append((entry.name, mesh.n_vertices, ours, theirs))
        print(f"{entry.name[:48]:48s} {mesh.n_vertices:>9d} v  defaults {ours:6.3f} s  "
              f"{args.override} {theirs:6.3f} s", flush=True)
    if not rows:
        print("describe_cost: no readable entry")
        return 1
    ours_s = np.array([r[2] for r in rows])
    theirs_s = np.array([r[3] for r in rows])
    print(f"\n{len(rows)} entries; CPU seconds, one thread: defaults {ours_s.sum():.2f} "
          f"(median {np.median(ours_s):.3f}), {args.override} {theirs_s.sum():.2f} "
          f"(median {np.median(theirs_s):.3f})")
    print(f"ratio of the totals {ours_s.sum() / theirs_s.sum():.3f}; median per-file ratio "
          f"{np.median(ours_s / theirs_s):.3f}")
    total = sum(stages.values())
    print("the defaults' stages, share of their wall time: "
          + ", ".join(f"{stage} {100 * seconds / total:.1f} %" for stage, seconds in stages.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
