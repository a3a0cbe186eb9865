"""The variants benchmarks/variants_detect.py makes of a base mesh, each with the relation it must be
found in: (kind, mesh, expected relation of the variant to its base, or None when it is the base that
must be found in the variant, see `plate_member`)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from app.core.decimation import quadric
from app.core.mesh import InvalidMeshError, Mesh, clean, load_mesh
from app.core.remeshing import isotropic_remesh
from app.core.variants.surface import objects, submesh

# every writer trimesh has for triangle meshes (gltf needs its .bin beside it: GLB covers glTF)
WRITERS = {"stl": "stl", "stl_ascii": "stl", "obj": "obj", "ply": "ply", "off": "off", "glb": "glb",
           "3mf": "3mf", "dae": "dae"}
NOISE = 0.002  # vertex noise, standard deviation / bounding-box diagonal
HOLE = 0.01  # area fraction punched out


def diagonal(mesh: Mesh) -> float:
    return float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))


def rigid(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    rotation = Rotation.random(random_state=rng).as_matrix()
    shift = rng.normal(size=3) * diagonal(mesh)
    return Mesh(mesh.vertices @ rotation.T + shift, mesh.faces)


def reexport(mesh: Mesh, writer: str) -> Mesh:
    data = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(file_type=writer)
    if isinstance(data, str):
        data = data.encode()
    return load_mesh(bytes(data), WRITERS[writer])


def decimate(mesh: Mesh, fraction: float) -> Mesh:
    """Quadric decimation to `fraction` of the vertices (on a unit-area copy: its thresholds are absolute)."""
    scale = np.sqrt(mesh.area())
    centre = mesh.vertices.mean(axis=0)
    unit = Mesh((mesh.vertices - centre) / scale, mesh.faces)
    out = quadric(unit, max(4, int(fraction * mesh.n_vertices)), aggressiveness=7.0)
    return clean(Mesh(out.vertices * scale + centre, out.faces))


def noisy(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    noise = rng.normal(scale=NOISE * diagonal(mesh), size=mesh.vertices.shape)
    return Mesh(mesh.vertices + noise, mesh.faces)


def punched(mesh: Mesh, rng: np.random.Generator) -> Mesh:
    """The faces nearest a random face centre removed, up to HOLE of the area."""
    centres = mesh.vertices[mesh.faces].mean(axis=1)
    areas = mesh.face_areas()
    start = centres[rng.choice(len(areas), p=areas / areas.sum())]
    order = np.argsort(np.linalg.norm(centres - start, axis=1))
    cut = order[: max(1, int(np.searchsorted(np.cumsum(areas[order]), HOLE * areas.sum())))]
    keep = np.ones(len(areas), bool)
    keep[cut] = False
    return clean(Mesh(mesh.vertices, mesh.faces[keep]))


def plate(meshes: list[Mesh], rng: np.random.Generator) -> Mesh:
    """The meshes side by side on a grid (each turned about z), 10 % of the widest footprint apart."""
    # the widest footprint whatever the turn: twice the largest distance from the centre in x-y
    reach = max(float(np.linalg.norm(m.vertices[:, :2] - m.vertices[:, :2].mean(axis=0), axis=1).max())
                for m in meshes)
    step = 2.2 * reach + 1e-9
    side = int(np.ceil(np.sqrt(len(meshes))))
    vs, fs, offset = [], [], 0
    for i, m in enumerate(meshes):
        turn = Rotation.from_euler("z", rng.uniform(0, 2 * np.pi)).as_matrix()
        v = (m.vertices - m.vertices.mean(axis=0)) @ turn.T
        v = v + [step * (i % side), step * (i // side), -v[:, 2].min()]
        vs.append(v)
        fs.append(m.faces + offset)
        offset += len(v)
    return Mesh(np.vstack(vs), np.vstack(fs))


def variants(base: Mesh, rng: np.random.Generator, full: bool) -> Iterator[tuple[str, Mesh, str]]:
    """(kind, variant, expected relation of the variant to the base); kinds that do not apply to the
    base (a decimation below 20 vertices, a remesh the remesher refuses) are left out."""
    for writer in WRITERS if full else ("stl", "obj", "ply", "glb", "3mf"):
        try:
            yield f"export:{writer}", reexport(base, writer), "identical"
        except (InvalidMeshError, ValueError, ImportError, KeyError, NotImplementedError):
            continue  # a writer that cannot carry this mesh (e.g. no lxml): not a detection miss
    yield "scale:25.4", Mesh(base.vertices * 25.4, base.faces), "rescaled"
    yield "scale:0.001", Mesh(base.vertices * 0.001, base.faces), "rescaled"
    yield "mirror", Mesh(base.vertices * [-1.0, 1.0, 1.0], base.faces[:, ::-1]), "mirrored"
    yield "rigid", rigid(base, rng), "moved"
    for fraction in (0.5, 0.1):
        if fraction * base.n_vertices >= 20:
            made = _made(decimate, base, fraction)
            if made is not None:
                yield f"decimate:{fraction:.0%}", made, "retriangulated"
    remeshed = isotropic_remesh(base, base.n_vertices)
    if remeshed is not base:
        yield "remesh", remeshed, "retriangulated"
    yield "noise", noisy(base, rng), "retriangulated"
    holed = _made(punched, base, rng)
    if holed is not None:
        yield "hole", holed, "retriangulated"
    yield "plate", plate([base] * int(rng.integers(2, 7)), rng), "contains"
    parts = objects(base)
    if len(parts) > 1:  # one object of a multi-object file
        yield "part", parts[0], "part_of"


def _made(make: Callable[..., Mesh], *args: object) -> Mesh | None:
    """make(*args), or None where it leaves no valid mesh (a decimation down to slivers)."""
    try:
        return make(*args)
    except InvalidMeshError:
        return None


def plate_member(base: Mesh, others: list[Mesh], rng: np.random.Generator) -> Mesh:
    """A print plate holding `base` among other models brought to its size: the base must be found as
    part_of it."""
    size = diagonal(base)
    return plate([base, *(Mesh(o.vertices * size / diagonal(o), o.faces) for o in others)], rng)


__all__ = ["diagonal", "plate_member", "submesh", "variants"]
