"""Labelled partial queries: each mesh of a collection cut by random planes, or punched with holes.

    python -m benchmarks.partial SRC OUT --band 60-85 [--cuts 1|2 | --holes | --views N] [--seed 0]

For every mesh of the labelled folder SRC (labels.csv: file,class; SRC may name a dataset under
SHAPEBAG_DATASETS, e.g. `shrec11-simplified`), OUT gets one partial mesh under the same relative name:
- cuts: one (or two) random planes (uniform normal; the offset aimed at a random kept fraction in the
  band); the faces whose centroid lies on the removed side are dropped. Triangles are not split, so the
  rim follows the triangulation (jagged at the scale of one edge), and the kept fraction is the true area
  of the faces kept, not the plane's ideal share;
- `--holes`: 1-3 discs (faces whose centroid is within r of a random vertex) punched out, r bisected
  so that the kept fraction lands in the band;
- `--views N`: what a scanner sees from random directions (uniform on the sphere), one more until the
  piece lands in the band, at most N: the faces whose centroid no other face hides from a viewer far
  along one of them (a ray cast from the centroid toward each viewer), as a one-sided scan is partial,
  with no plane and no disc. A mesh no such draw lands in the band for is left out (and named).
Then the largest connected piece is kept. Its area over the whole mesh's area must lie in the band, else
new planes (discs) are drawn from the mesh's own random stream (seed, row), so the output does not depend
on the order of the work. OUT gets labels.csv (file,class), usable as `shapebag evaluate SRC --queries
OUT`, and partial.csv (file,class,kept_fraction,cuts; cuts is 0 for holes and views). Write OUT outside the
repository (var/ is ignored); the meshes are never committed.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from app.core.cleaning import vertex_components
from app.core.mesh import Mesh, clean, load_mesh
from app.core.meshdata import InvalidMeshError
from app.datasets import locate
from app.datasets.folder import read_labelled_folder
from app.storage.blobs import atomic_write
from benchmarks.variants import _obj_text

BANDS = {"60-85": (0.60, 0.85), "40-60": (0.40, 0.60)}
TRIES = 200  # planes (disc sets) drawn per mesh before giving up
HOLES = (1, 3)


RAY_CHUNK = 256  # face centroids whose rays are tested against every triangle at once


class NoPieceInBand(RuntimeError):
    """No draw of planes (discs) left a largest piece with its area fraction in the band."""


def face_areas(mesh: Mesh) -> np.ndarray:
    """(f,) area of each face."""
    t = mesh.vertices[mesh.faces]  # (f, 3, 3)
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)


def largest_piece(mesh: Mesh, keep: np.ndarray) -> Mesh:
    """The largest-area connected piece (faces sharing a vertex) of the faces where keep (f,) bool."""
    sub = Mesh(mesh.vertices, mesh.faces[keep])
    if len(sub.faces) == 0:
        return sub
    labels = vertex_components(sub)[sub.faces[:, 0]]  # (f',) component of each kept face
    best = np.bincount(labels, weights=face_areas(sub)).argmax()
    try:
        return clean(Mesh(sub.vertices, sub.faces[labels == best]), 0.0)
    except InvalidMeshError:  # a few faces left: an empty piece, outside any band
        return Mesh(sub.vertices, sub.faces[:0])


def _plane_keep(centroids: np.ndarray, areas: np.ndarray, alive: np.ndarray, target: float,
                rng: np.random.Generator) -> np.ndarray:
    """Keep mask (f,) of a random-normal plane whose positive side holds `target` of the total area,
    counting only the faces still alive. centroids (f, 3), areas (f,), alive (f,) bool."""
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    h = centroids @ normal  # (f,)
    order = np.argsort(-h)
    kept_area = np.cumsum(np.where(alive, areas, 0.0)[order])  # area above each height, highest first
    k = int(np.searchsorted(kept_area, target * areas.sum()))
    threshold = h[order[min(k, len(order) - 1)]]
    return alive & (h >= threshold)


def cut(mesh: Mesh, band: tuple[float, float], rng: np.random.Generator, cuts: int = 1) -> tuple[Mesh, float]:
    """The largest piece left by `cuts` random planes with area fraction in `band`, and that fraction."""
    areas = face_areas(mesh)
    total = areas.sum()
    centroids = mesh.vertices[mesh.faces].mean(axis=1)  # (f, 3)
    for _ in range(TRIES):
        goal = rng.uniform(*band)
        keep = np.ones(len(areas), dtype=bool)
        for j in range(1, cuts + 1):  # two cuts: the first keeps sqrt(goal), the second goal
            keep = _plane_keep(centroids, areas, keep, goal ** (j / cuts), rng)
        piece = largest_piece(mesh, keep)
        fraction = float(face_areas(piece).sum() / total) if len(piece.faces) else 0.0
        if band[0] <= fraction <= band[1]:
            return piece, fraction
    raise NoPieceInBand(f"no {cuts}-plane cut kept {band[0]:.0%}-{band[1]:.0%} in {TRIES} tries")


def punch(mesh: Mesh, band: tuple[float, float], rng: np.random.Generator,
          holes: tuple[int, int] = HOLES) -> tuple[Mesh, float]:
    """The largest piece left by 1-3 discs punched out (radius bisected to aim at a random fraction in
    `band`), with its area fraction in `band`, and that fraction."""
    areas = face_areas(mesh)
    total = areas.sum()
    centroids = mesh.vertices[mesh.faces].mean(axis=1)  # (f, 3)
    diag = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    for _ in range(TRIES):
        goal = rng.uniform(*band)
        centres = mesh.vertices[rng.integers(mesh.n_vertices, size=int(rng.integers(holes[0], holes[1] + 1)))]
        dist = np.linalg.norm(centroids[:, None, :] - centres[None], axis=2).min(axis=1)  # (f,)
        lo, hi = 0.0, diag
        piece, fraction = mesh, 1.0
        for _ in range(30):  # the kept area falls as the radius grows
            r = 0.5 * (lo + hi)
            piece = largest_piece(mesh, dist > r)
            fraction = float(face_areas(piece).sum() / total) if len(piece.faces) else 0.0
            if band[0] <= fraction <= band[1] and abs(fraction - goal) < 0.01:
                break
            lo, hi = (r, hi) if fraction > goal else (lo, r)
        if band[0] <= fraction <= band[1]:
            return piece, fraction
    raise NoPieceInBand(f"no {holes[0]}-{holes[1]} holes kept {band[0]:.0%}-{band[1]:.0%} in {TRIES} tries")


def visible(mesh: Mesh, direction: np.ndarray) -> np.ndarray:
    """(f,) bool: faces whose centroid a viewer far along `direction` (3,) sees, that is whose ray from
    the centroid toward the viewer meets no other triangle (Möller-Trumbore against every face)."""
    tri = mesh.vertices[mesh.faces]  # (f, 3, 3)
    a, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d = direction / np.linalg.norm(direction)
    p = np.cross(d, e2)  # (f, 3): the ray direction is the same for every origin
    det = np.einsum("fi,fi->f", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    centroids = tri.mean(axis=1)
    scale = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    seen = np.ones(len(tri), dtype=bool)
    for start in range(0, len(tri), RAY_CHUNK):
        origin = centroids[start:start + RAY_CHUNK] + 1e-7 * scale * d  # (c, 3), off its own face
        s = origin[:, None, :] - a[None]  # (c, f, 3)
        u = np.einsum("cfi,fi->cf", s, p) * inv
        q = np.cross(s, e1[None])  # (c, f, 3)
        v = (q @ d) * inv
        t = np.einsum("cfi,fi->cf", q, e2) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9 * scale)
        rows = np.arange(len(origin))
        hit[rows, start + rows] = False  # its own face
        seen[start:start + RAY_CHUNK] = ~hit.any(axis=1)
    return seen


def scan(mesh: Mesh, band: tuple[float, float], rng: np.random.Generator, views: int) -> tuple[Mesh, float]:
    """The largest piece of what random directions see, one more at a time up to `views`, with its area
    fraction in `band` (the first that lands in it), and that fraction."""
    areas = face_areas(mesh)
    total = areas.sum()
    for _ in range(TRIES):
        keep = np.zeros(len(areas), dtype=bool)
        for _ in range(views):  # one more viewer until the piece reaches the band (or passes it)
            keep |= visible(mesh, rng.normal(size=3))
            piece = largest_piece(mesh, keep)
            fraction = float(face_areas(piece).sum() / total) if len(piece.faces) else 0.0
            if band[0] <= fraction <= band[1]:
                return piece, fraction
            if fraction > band[1]:
                break
    raise NoPieceInBand(f"no {views} views saw {band[0]:.0%}-{band[1]:.0%} in {TRIES} tries")


def parse_band(text: str) -> tuple[float, float]:
    """'60-85' -> (0.60, 0.85): percentages of the area kept."""
    lo, _, hi = text.partition("-")
    band = (float(lo) / 100, float(hi) / 100)
    if not 0 < band[0] < band[1] <= 1:
        raise ValueError(f"band must be LO-HI percentages with 0 < LO < HI <= 100, not {text!r}")
    return band


def generate(src: Path | str, out: Path | str, band: tuple[float, float], cuts: int = 1,
             holes: bool = False, seed: int = 0, views: int = 0) -> Path:
    """Write the partial mesh of every mesh of the labelled folder `src` under `out`; return `out`."""
    if cuts not in (1, 2):
        raise ValueError(f"cuts must be 1 or 2, not {cuts}")
    rows = read_labelled_folder(src)
    root, dest = Path(src).resolve(), Path(out)
    labels, table, skipped = [], [], []
    for i, row in enumerate(rows):
        rel = row.path.relative_to(root).as_posix()
        rng = np.random.default_rng([seed, i])
        mesh = load_mesh(row.path)
        if views:
            try:
                piece, fraction = scan(mesh, band, rng, views)
            except NoPieceInBand:  # a shape no few viewers see that much of (its limbs hide each other)
                skipped.append(rel)
                continue
        else:
            piece, fraction = punch(mesh, band, rng) if holes else cut(mesh, band, rng, cuts)
        target = (dest / rel).with_suffix(".obj")
        target.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(target, _obj_text(piece).encode())
        name = target.relative_to(dest).as_posix()
        labels.append(f"{name},{row.label}\n")
        table.append(f"{name},{row.label},{fraction:.4f},{0 if holes or views else cuts}\n")
    atomic_write(dest / "partial.csv", ("file,class,kept_fraction,cuts\n" + "".join(table)).encode())
    atomic_write(dest / "labels.csv", ("file,class\n" + "".join(labels)).encode())  # last: a complete folder
    if skipped:
        print(f"{len(skipped)} meshes with no view piece in the band, left out: {', '.join(skipped[:10])}")
    return dest


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src", help="labelled folder (labels.csv: file,class), or a dataset name")
    p.add_argument("out", type=Path, help="output folder (outside the repository, or under var/)")
    p.add_argument("--band", default="60-85", help="kept area, percent: LO-HI (60-85, 40-60)")
    p.add_argument("--cuts", type=int, choices=(1, 2), default=1)
    p.add_argument("--holes", action="store_true", help="punch 1-3 discs instead of cutting")
    p.add_argument("--views", type=int, default=0, help="what up to N random viewers see, instead of cutting")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    src = Path(args.src)
    if not src.is_dir() and args.src in locate.KNOWN:
        src = locate.require(args.src)
    out = generate(src, args.out, parse_band(args.band), args.cuts, args.holes, args.seed, args.views)
    print(f"wrote {out / 'labels.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
