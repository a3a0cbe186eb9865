"""Labelled variants of a mesh collection: the same surfaces, another triangulation, or noise.

    python -m benchmarks.variants SRC OUT [--kind remesh|noise] [--seed 0] [--nsr 0.01]

`remesh`: every mesh is midpoint-subdivided to at least 16k vertices (sample points on the same
surface), then decimated with quadric error to a random 1k-8k vertices: a new, irregular triangulation
of the same surface at another resolution. `noise`: Gaussian vertex noise (NSR, as `evaluate --noise`).
OUT gets the same relative file names and labels.csv (file,class), so it can be evaluated on its own
or as queries against SRC (`shapebag evaluate SRC --queries OUT`). Each mesh has its own random
stream (seed, row), so the output does not depend on the order of the work. Write OUT outside the
repository (var/ is ignored); the meshes are never committed.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh

from app.core.mesh import Mesh, clean, load_mesh
from app.core.resolution import perturb
from app.datasets.folder import read_labelled_folder
from app.storage.blobs import atomic_write

KINDS = ("remesh", "noise")
FINE_VERTICES = 16_000
VERTEX_RANGE = (1_000, 8_000)


def retriangulate(mesh: Mesh, rng: np.random.Generator, fine: int = FINE_VERTICES,
                  vertex_range: tuple[int, int] = VERTEX_RANGE) -> Mesh:
    """Same surface, new triangulation: midpoint-subdivide to >= `fine` vertices, then quadric-decimate
    to a random vertex count in `vertex_range` (uniform in log). vertices (n, 3), faces (f, 3)."""
    import fast_simplification  # compiled extension, as in app.core.resolution

    v, f = mesh.vertices, mesh.faces
    while len(v) < fine:
        v, f = trimesh.remesh.subdivide(v, f)
    target = int(np.exp(rng.uniform(*np.log(vertex_range))))
    # agg=3 keeps the meshes watertight; one pass may stop short of the target, which is still a
    # triangulation unlike the source's, at a random resolution
    v2, f2 = fast_simplification.simplify(np.asarray(v, np.float32), np.asarray(f, np.int32),
                                          target_reduction=1.0 - target / len(v), agg=3)
    return clean(Mesh(np.asarray(v2, np.float64), np.asarray(f2, np.int64)))


def generate(src: Path | str, out: Path | str, kind: str = "remesh", seed: int = 0,
             nsr: float = 0.01, vertex_range: tuple[int, int] = VERTEX_RANGE) -> Path:
    """Write the `kind` variant of every mesh of the labelled folder `src` under `out`; return `out`."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, not {kind!r}")
    rows = read_labelled_folder(src)
    root, dest = Path(src).resolve(), Path(out)
    lines = []
    for i, row in enumerate(rows):
        rel = row.path.relative_to(root).as_posix()
        rng = np.random.default_rng([seed, i])
        mesh = load_mesh(row.path)
        if kind == "remesh":
            mesh = retriangulate(mesh, rng, vertex_range=vertex_range)
        else:
            mesh = perturb(mesh, nsr, int(rng.integers(2**63)))
        target = (dest / rel).with_suffix(".obj")
        target.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(target, _obj_text(mesh).encode())
        lines.append(f"{target.relative_to(dest).as_posix()},{row.label}\n")
    atomic_write(dest / "labels.csv", ("file,class\n" + "".join(lines)).encode())  # last: a complete folder
    return dest


def _obj_text(mesh: Mesh) -> str:
    out = [f"v {x:.8g} {y:.8g} {z:.8g}\n" for x, y, z in mesh.vertices]
    out += [f"f {a} {b} {c}\n" for a, b, c in mesh.faces + 1]
    return "".join(out)


def write_labelled(dest: Path, names: list[str], per_class: int,
                   make: Callable[[int, str, int], Mesh]) -> Path:
    """Write make(class index, class name, instance) as dest/<class>/<class>_NN.obj for every class and
    instance, then labels.csv (file,class) last: a folder with labels.csv is complete. Returns dest."""
    lines = []
    for c, name in enumerate(names):
        (dest / name).mkdir(parents=True, exist_ok=True)
        for i in range(per_class):
            rel = f"{name}/{name}_{i:02d}.obj"
            atomic_write(dest / rel, _obj_text(make(c, name, i)).encode())
            lines.append(f"{rel},{name}\n")
    atomic_write(dest / "labels.csv", ("file,class\n" + "".join(lines)).encode())
    return dest


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src", type=Path, help="labelled folder (labels.csv: file,class)")
    p.add_argument("out", type=Path, help="output folder (outside the repository, or under var/)")
    p.add_argument("--kind", choices=KINDS, default="remesh")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--nsr", type=float, default=0.01, help="noise variance / coordinate variance (noise)")
    args = p.parse_args(argv)
    out = generate(args.src, args.out, args.kind, args.seed, args.nsr)
    print(f"wrote {out / 'labels.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
