"""High-resolution test meshes made from SHREC'11: Loop subdivision, then quadric simplification to size.

The SHREC'11 copy in the shared datasets folder is decimated to ~250 vertices; the original collection
has ~10k. Subdividing (250 -> 1k -> 4k -> 16k -> 64k -> 256k) and simplifying to the exact target
gives smooth, watertight, single-component meshes at the resolutions a user would upload.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import trimesh

from app.core.mesh import Mesh, load_mesh
from app.core.resolution import simplify
from app.datasets import locate


def dataset_dir() -> Path:
    """SHAPEBAG_DATASETS/shrec11-simplified (app/datasets/locate.py)."""
    return locate.dataset_dir("shrec11-simplified")


def labelled_files(root: Path | None = None) -> list[tuple[Path, str]]:
    """[(path, class)] from labels.csv, in file order."""
    root = root or locate.require("shrec11-simplified")  # DatasetMissing: names it and how to get it
    with open(root / "labels.csv", newline="") as fh:
        return [(root / row["file"], row["class"]) for row in csv.DictReader(fh)]


def pick(classes: int, per_class: int, root: Path | None = None) -> list[tuple[Path, str]]:
    """The first `per_class` meshes of the first `classes` classes (alphabetical): a fixed subset."""
    by_class: dict[str, list[Path]] = {}
    for path, label in labelled_files(root):
        by_class.setdefault(label, []).append(path)
    out = []
    for label in sorted(by_class)[:classes]:
        out += [(p, label) for p in sorted(by_class[label])[:per_class]]
    return out


def upsample(mesh: Mesh, target_vertices: int) -> Mesh:
    """Loop-subdivide until >= target, then quadric-simplify down to ~target vertices."""
    v, f = mesh.vertices, mesh.faces
    while len(v) < target_vertices:
        v, f = trimesh.remesh.subdivide_loop(v, f, iterations=1)
    out = Mesh(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64))
    if out.n_vertices > 1.05 * target_vertices:
        out = simplify(out, target_vertices)
    return out


def write(mesh: Mesh, path: Path) -> Path:
    """Write .ply (binary little-endian) or .obj, by the suffix of `path`."""
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    tm.export(path)
    return path


def make_set(
    sources: Iterable[tuple[Path, str]],
    target_vertices: int,
    out_dir: Path,
    formats: tuple[str, ...] = ("ply",),
) -> list[dict]:
    """Upsample each source mesh to `target_vertices`; [{label, source, vertices, ply?, obj?}]."""
    rows = []
    for i, (src, label) in enumerate(sources):
        mesh = upsample(load_mesh(src), target_vertices)
        row: dict = {"label": label, "source": str(src), "vertices": mesh.n_vertices}
        for fmt in formats:
            row[fmt] = str(write(mesh, out_dir / f"{i:04d}_{label}_{target_vertices}.{fmt}"))
        rows.append(row)
    return rows
