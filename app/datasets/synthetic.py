"""A labelled corpus of articulated shapes, generated in seconds, for a machine with no dataset.

Each class is a body plan (app/datasets/bodyplans.py): a skeleton of tapered capsules. An instance
jitters the proportions a little, bends every joint by a random angle (a near-isometric deformation:
the HKS should not care), builds the surface as the zero level of a smooth union of the capsules'
distance fields, extracts it with marching cubes, and applies a random rigid motion and uniform scale.

    generate(Path("var/synthetic"))  ->  var/synthetic/labels.csv + var/synthetic/<class>/<class>_NN.obj
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from skimage.measure import marching_cubes

from app.datasets.bodyplans import PLANS, Chain
from app.datasets.folder import LABELS_FILE, read_labelled_folder

GRID = 46  # voxels along the longest side (at least: thin limbs refine it)
MAX_VERTICES = 3000  # finer marching-cubes output is decimated to this
BLEND = 0.045  # smooth-union radius (body units): joints fuse without visible creases
Segment = tuple[np.ndarray, np.ndarray, float, float]  # start (3,), end (3,), r_start, r_end
Frame = tuple[np.ndarray, np.ndarray]  # rest start (3,), rotation (3, 3) of one segment


def generate(out_dir: Path | str, classes: int = 6, per_class: int = 8, seed: int = 0) -> Path:
    """Write `classes` x `per_class` OBJ meshes and labels.csv (file,class) under out_dir; return it.

    The same arguments always give the same files. Each shape has its own random stream, derived
    from (seed, class, instance), so asking for more classes or instances leaves the others unchanged.
    labels.csv is written last (atomically): a folder with labels.csv is complete.
    """
    names = list(PLANS)
    if not 1 <= classes <= len(names):
        raise ValueError(f"classes must be between 1 and {len(names)} (the body plans: {', '.join(names)})")
    if per_class < 1:
        raise ValueError("per_class must be at least 1")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for c, name in enumerate(names[:classes]):
        (out / name).mkdir(exist_ok=True)
        for i in range(per_class):
            vertices, faces = make_shape(name, np.random.default_rng([seed, c, i]))
            rel = f"{name}/{name}_{i:02d}.obj"
            _write_obj(out / rel, vertices, faces)
            rows.append(f"{rel},{name}\n")
    _atomic_write(out / "labels.csv", "file,class\n" + "".join(rows))
    return out


def make_shape(plan: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One random instance of a body plan -> vertices (n, 3) float64, faces (f, 3) int64."""
    segments = pose(PLANS[plan](), rng)
    vertices, faces = surface(segments)
    return random_motion(vertices, rng), faces


def random_motion(vertices: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) -> (n, 3): centred, then a random rotation, a scale in [0.5, 2] and a shift in [-1, 1]^3."""
    rotation = Rotation.random(random_state=rng).as_matrix()
    scale = rng.uniform(0.5, 2.0)
    shift = rng.uniform(-1.0, 1.0, size=3)
    return (vertices - vertices.mean(axis=0)) @ rotation.T * scale + shift


def pose(chains: list[Chain], rng: np.random.Generator) -> list[Segment]:
    """Jitter proportions and bend each joint: forward kinematics along every chain."""
    return pose_frames(chains, rng)[0]


def pose_frames(chains: list[Chain], rng: np.random.Generator,
                jitter: bool = True) -> tuple[list[Segment], list[Frame]]:
    """pose(), with each segment's rigid frame: a point x of the rest pose attached to segment s moves
    to start_s + R_s (x - rest_start_s) (exact for the rest pose's own segment when jitter is False:
    lengths and radii then stay those of the plan, so a template can be skinned by these frames).
    The random stream is the same with and without jitter."""
    segments: list[Segment] = []
    frames: list[Frame] = []
    for chain in chains:
        stretch = rng.uniform(0.92, 1.08)
        thick = rng.uniform(0.92, 1.08)
        if not jitter:
            stretch = thick = 1.0
        rot = np.eye(3)
        p = np.asarray(chain.anchor, dtype=float)
        rest = p.copy()
        for d, length, (r0, r1), bend in zip(chain.dirs, chain.lengths, chain.radii, chain.bend, strict=True):
            direction = _unit(np.asarray(d, dtype=float))
            axis_draw = rng.normal(size=3)  # drawn for every joint: the stream does not depend on bends
            angle = np.radians(rng.uniform(-bend, bend))
            if bend > 0:
                along = rot @ direction
                axis = rot @ np.asarray(chain.hinge, dtype=float) if chain.hinge is not None else axis_draw
                axis = axis - along * (axis @ along)  # bend about an axis across the segment
                if np.linalg.norm(axis) > 1e-9:
                    rot = Rotation.from_rotvec(_unit(axis) * angle).as_matrix() @ rot
            end = p + rot @ direction * length * stretch
            segments.append((p, end, r0 * thick, r1 * thick))
            frames.append((rest, rot.copy()))
            p, rest = end, rest + direction * length
    return segments, frames


def surface(segments: list[Segment], grid: int = GRID, blend: float = BLEND,
            max_vertices: int | None = MAX_VERTICES) -> tuple[np.ndarray, np.ndarray]:
    """Zero level set of the smooth union of tapered capsules -> vertices (n, 3), faces (f, 3).

    Decimated to `max_vertices` when marching cubes gives more (None: kept as extracted).

    Field: F(x) = -blend * log(sum_i exp(-d_i(x) / blend)), d_i the capsule distances (a soft min,
    independent of the order of the capsules, C-infinity where capsules meet). A capsule's term is
    negligible beyond ~12 blend radii, so each is evaluated on its own box of the grid only.
    """
    ends = np.array([[s[0], s[1]] for s in segments]).reshape(-1, 3)
    rmax = max(max(s[2], s[3]) for s in segments)
    rmin = min(min(s[2], s[3]) for s in segments)
    lo, hi = ends.min(axis=0) - rmax, ends.max(axis=0) + rmax
    h = min(float((hi - lo).max()) / grid, rmin / 1.6)  # the thinnest limb spans >= 3 voxels
    lo = lo - 2.5 * h  # keep the surface off the grid border: closed meshes
    shape = tuple(int(n) for n in np.ceil((hi - lo) / h + 2.5) + 1)
    total = np.zeros(shape, dtype=np.float64)  # sum_i exp(-d_i / blend)
    reach = 12.0 * blend
    for a, b, r0, r1 in segments:
        box_lo = np.maximum(np.floor((np.minimum(a, b) - max(r0, r1) - reach - lo) / h).astype(int), 0)
        box_hi = np.minimum(np.ceil((np.maximum(a, b) + max(r0, r1) + reach - lo) / h).astype(int) + 1, shape)
        axes = [lo[k] + h * np.arange(box_lo[k], box_hi[k]) for k in range(3)]
        pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        d = capsule_distance(pts, a, b, r0, r1)
        block = tuple(slice(box_lo[k], box_hi[k]) for k in range(3))
        total[block] += np.exp(-d / blend).reshape(total[block].shape)
    with np.errstate(divide="ignore"):
        field = np.where(total > 0, -blend * np.log(total), reach)
    verts, faces, _, _ = marching_cubes(field, level=0.0, spacing=(h, h, h))
    verts = verts.astype(np.float64) + lo
    faces = faces.astype(np.int64)
    if max_vertices is not None and len(verts) > max_vertices:
        verts, faces = _simplify(verts, faces, max_vertices)
    if _signed_volume(verts, faces) < 0:  # outward normals whatever marching cubes' convention
        faces = faces[:, ::-1].copy()
    return verts, faces


def _simplify(verts: np.ndarray, faces: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadric decimation to about `target` vertices (marching cubes over-samples flat parts)."""
    import fast_simplification  # compiled; a dependency of the core already

    v, f = fast_simplification.simplify(
        verts.astype(np.float32), faces.astype(np.int32), target_reduction=1.0 - target / len(verts), agg=3
    )
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


def capsule_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, r0: float, r1: float) -> np.ndarray:
    """(N,) distance from points p (N, 3) to the capsule a-b with radius r0 -> r1 along it."""
    ab = b - a
    ap = p - a
    t = np.clip(ap @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.sqrt(((ap - t[:, None] * ab) ** 2).sum(axis=1)) - (r0 + (r1 - r0) * t)


def _signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    t = v[f]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x)


def refine(src_dir: Path | str, out_dir: Path | str, min_vertices: int) -> Path:
    """Copy a labelled folder of OBJ meshes to out_dir, each mesh midpoint-subdivided until it has at
    least `min_vertices` vertices: the same surfaces (every new vertex is an edge midpoint) at a scan's
    resolution. The shipped vocabulary's recipe describes its corpus at both ends of the low-pass ramp
    (DescribeParams.antialias_start/full): as generated, and refined past the ramp's end."""
    import trimesh

    src, out = Path(src_dir).resolve(), Path(out_dir)  # the folder reader gives resolved paths
    for item in read_labelled_folder(src):
        rel = item.path.relative_to(src)
        mesh = trimesh.load(item.path, force="mesh", process=False)
        if not isinstance(mesh, trimesh.Trimesh):
            raise ValueError(f"{item.path} is not one triangle mesh")
        vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        while len(vertices) < min_vertices:
            vertices, faces = trimesh.remesh.subdivide(vertices, faces)
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        text = trimesh.exchange.obj.export_obj(trimesh.Trimesh(vertices, faces, process=False))
        _atomic_write(out / rel, text)
    _atomic_write(out / LABELS_FILE, (src / LABELS_FILE).read_text())  # last: labels.csv means complete
    return out


def _write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in vertices]
    lines += [f"f {a} {b} {c}\n" for a, b, c in faces + 1]
    _atomic_write(path, "".join(lines))


def _atomic_write(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
