"""Before/after of the speed work in app/core/mesh.py and app/core/spectrum.py, on one 160k-vertex mesh.

"before" is app/core/mesh.py as of a git revision (default: the project's first commit), loaded from
`git show`; "after" is the working tree. The eigensolve compares method="exact" (float64 LAPACK,
what "dense" was before) with the mixed-precision "dense". CPU seconds, median of `--repeats`.

    python -m benchmarks.before_after [--rev 3da44ec] [--vertices 160000]
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import REPO_ROOT, pin_threads, table, write_json

FIRST_COMMIT = "3da44ec"


def _old_module(rev: str, directory: Path):
    source = subprocess.run(
        ["git", "show", f"{rev}:app/core/mesh.py"], cwd=REPO_ROOT, check=True, capture_output=True, text=True
    ).stdout
    path = directory / "mesh_before.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("mesh_before", path)
    if spec is None or spec.loader is None:
        raise RuntimeError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _cpu(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return statistics.median(times)


def run(rev: str, vertices: int, repeats: int) -> dict:
    pin_threads(1)
    from types import SimpleNamespace

    from app.core import mesh, resolution

    # the resolution policy moved from mesh.py to resolution.py: "after" is both, as one namespace
    after = SimpleNamespace(**{**vars(mesh), **vars(resolution)})
    from app.core import spectrum
    from app.core.laplacian import cotangent_laplacian
    from benchmarks.meshes import pick, upsample, write

    tmp = Path(tempfile.mkdtemp(prefix="shapebag-before-after-"))
    before = _old_module(rev, tmp)
    mesh = upsample(after.load_mesh(pick(1, 1)[0][0]), vertices)
    rows = []
    for fmt in ("ply", "obj"):
        data = write(mesh, tmp / f"m.{fmt}").read_bytes()
        for label, mod in (("before", before), ("after", after)):
            v, f = mod._parse(data, fmt)
            cleaned = mod.clean(mod.validate(v, f))
            resampled = mod.to_resolution(cleaned, 1000)
            rows.append(
                {
                    "format": fmt,
                    "code": label,
                    "parse_s": _cpu(lambda m=mod, d=data, t=fmt: m._parse(d, t), repeats),
                    "validate_clean_s": _cpu(lambda m=mod, a=v, b=f: m.clean(m.validate(a, b)), repeats),
                    "resample_s": _cpu(
                        lambda m=mod, c=cleaned: m.to_resolution(c, 1000), max(1, repeats // 2)
                    ),
                    "resampled_vertices": resampled.n_vertices,
                }
            )
    work = after.normalize_scale(after.to_resolution(after.load_mesh(pick(1, 1)[0][0]), 1000))
    stiffness, mass = cotangent_laplacian(work.vertices, work.faces)
    eigen = {
        "vertices": work.n_vertices,
        "exact_s": _cpu(lambda: spectrum.smallest_eigenpairs(stiffness, mass, 300, method="exact"), repeats),
        "mixed_s": _cpu(lambda: spectrum.smallest_eigenpairs(stiffness, mass, 300, method="dense"), repeats),
    }
    print(table(rows, title=f"load/clean/resample of a {mesh.n_vertices}-vertex mesh, CPU s, {rev} vs now"))
    print(table([eigen], title="eigensolve k=300 at the canonical resolution, CPU s"))
    path = write_json("before-after", {"rev": rev, "rows": rows, "eigen": eigen})
    print(f"wrote {path}")
    return {"rows": rows, "eigen": eigen}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rev", default=FIRST_COMMIT, help="git revision of the 'before' mesh.py")
    ap.add_argument("--vertices", type=int, default=160_000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    run(args.rev, args.vertices, args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
