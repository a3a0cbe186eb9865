"""A labelled, scan-like corpus: the synthetic body plans as a range scanner would hand them over.

    python -m benchmarks.scans OUT [--classes 8] [--per-class 12] [--seed 0]
        [--holes MIN,MAX] [--noise S] [--vertices MIN,MAX] [--grid N]

The synthetic corpus (app.datasets.synthetic) is decimated to 3,000 vertices and closed, so the
pipeline reaches its canonical 1,000 vertices with a mild, near-uniform decimation. Scans are not like
that: 4k-50k vertices, open where the scanner saw nothing, a little sensor noise. Each shape here is a
random instance of a body plan (its own stream: (seed, class, index, 7), so not the synthetic corpus's
instances), extracted on a grid fine enough for 13k-46k vertices, then
- holes: 1-3 discs cut out (faces within 3-7 % of the bounding-box diagonal of a random vertex),
  and the largest remaining piece kept (a hole across a thin limb takes the limb's end with it);
- sensor noise: displacement along the vertex normal, σ = 0.1 % of the diagonal;
- a random resolution: quadric-decimated to 4k-40k vertices (log-uniform; a coarser extraction is
  kept as it is).
So the pipeline's decimation does the 4x-40x reduction that held-out scans need, on open
surfaces. `--holes 0,0 --noise 0` gives the closed, clean surfaces at the same resolutions: the figure
the holes and the noise are measured against. Write OUT outside the repository (var/ is ignored); the
meshes are never committed.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh

from app.core.cleaning import vertex_components
from app.core.mesh import Mesh, clean
from app.datasets.bodyplans import PLANS
from app.datasets.synthetic import _simplify, pose, random_motion, surface
from benchmarks.variants import write_labelled

FINE_GRID = 200  # voxels along the longest side: ~13k-46k vertices from marching cubes
VERTEX_RANGE = (4_000, 40_000)
HOLE_RADIUS = (0.03, 0.07)  # fraction of the bounding-box diagonal
NOISE = 0.001  # σ of the normal displacement, fraction of the diagonal
HOLES = (1, 3)  # how many discs are cut out: at least, at most


def scan_shape(plan: str, rng: np.random.Generator, grid: int = FINE_GRID, holes: tuple[int, int] = HOLES,
               noise: float = NOISE, vertex_range: tuple[int, int] = VERTEX_RANGE) -> Mesh:
    """One scan-like instance: fine surface, holes, normal noise, random resolution, rigid motion."""
    segments = pose(PLANS[plan](), rng)
    v, f = surface(segments, grid=grid, max_vertices=None)
    mesh = _with_holes(Mesh(random_motion(v, rng), f), rng, holes)
    diag = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    normals = np.asarray(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).vertex_normals)
    mesh = Mesh(mesh.vertices + normals * rng.normal(size=(mesh.n_vertices, 1)) * noise * diag, mesh.faces)
    return _decimate(mesh, int(np.exp(rng.uniform(*np.log(vertex_range)))))


def _with_holes(mesh: Mesh, rng: np.random.Generator, holes: tuple[int, int]) -> Mesh:
    """Cut holes[0]-holes[1] discs out and keep the largest connected piece."""
    v, f = mesh.vertices, mesh.faces
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    centroids = v[f].mean(axis=1)  # (f, 3)
    keep = np.ones(len(f), dtype=bool)
    for _ in range(int(rng.integers(holes[0], holes[1] + 1))):
        centre = v[rng.integers(len(v))]
        radius = rng.uniform(*HOLE_RADIUS) * diag
        keep &= np.linalg.norm(centroids - centre, axis=1) > radius
    f = f[keep]
    labels = vertex_components(Mesh(v, f))
    used = np.unique(f)
    biggest = np.bincount(labels[used]).argmax()
    f = f[labels[f[:, 0]] == biggest]
    return clean(Mesh(v, f))


def _decimate(mesh: Mesh, target: int) -> Mesh:
    if mesh.n_vertices <= target:
        return mesh
    return clean(Mesh(*_simplify(mesh.vertices, mesh.faces, target)))


def generate(out: Path | str, classes: int = 8, per_class: int = 12, seed: int = 0,
             holes: tuple[int, int] = HOLES, noise: float = NOISE,
             vertex_range: tuple[int, int] = VERTEX_RANGE, grid: int = FINE_GRID) -> Path:
    """Write classes x per_class scan-like OBJ meshes and labels.csv under `out`; return it."""
    def make(c: int, name: str, i: int) -> Mesh:
        rng = np.random.default_rng([seed, c, i, 7])  # not the synthetic corpus's instances
        return scan_shape(name, rng, grid=grid, holes=holes, noise=noise, vertex_range=vertex_range)

    return write_labelled(Path(out), list(PLANS)[:classes], per_class, make)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out")
    p.add_argument("--classes", type=int, default=8)
    p.add_argument("--per-class", type=int, default=12)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--holes", default=f"{HOLES[0]},{HOLES[1]}", help="MIN,MAX discs cut out per shape")
    p.add_argument("--noise", type=float, default=NOISE, help="normal noise σ / bounding-box diagonal")
    p.add_argument("--vertices", default=f"{VERTEX_RANGE[0]},{VERTEX_RANGE[1]}", help="MIN,MAX resolution")
    p.add_argument("--grid", type=int, default=FINE_GRID, help="marching-cubes voxels along the longest side")
    a = p.parse_args(argv)
    lo, hi = (int(x) for x in a.holes.split(","))
    vlo, vhi = (int(x) for x in a.vertices.split(","))
    out = generate(a.out, a.classes, a.per_class, a.seed, (lo, hi), a.noise, (vlo, vhi), a.grid)
    print("wrote", out / "labels.csv")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
