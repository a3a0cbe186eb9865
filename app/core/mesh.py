"""Triangle meshes in: load, validate, clean, and bring to a canonical resolution.

Everything a user can upload passes through :func:`load_mesh`, which raises :class:`InvalidMeshError`
with a sentence a user understands. The numerical core downstream may then assume a finite, indexed,
non-degenerate triangle mesh with positive area.
"""

from __future__ import annotations

import io
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import trimesh

SUPPORTED_FORMATS: tuple[str, ...] = ("obj", "off", "ply", "stl", "glb")
MIN_VERTICES = 4
MIN_FACES = 4


class InvalidMeshError(ValueError):
    """The input cannot be used as a triangle mesh; the message says why, in a user's words."""


@dataclass(frozen=True)
class Mesh:
    """An indexed triangle mesh.

    vertices : (n, 3) float64
    faces    : (f, 3) int64, indices into vertices
    """

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def face_areas(self) -> np.ndarray:
        """(f,) float64 triangle areas."""
        v = self.vertices[self.faces]
        return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)

    def area(self) -> float:
        return float(self.face_areas().sum())


def detect_format(name_or_type: str) -> str:
    """'chair.OBJ' / 'obj' / '.obj' -> 'obj'; raises InvalidMeshError for unsupported formats."""
    ext = name_or_type.rsplit(".", 1)[-1].lower().strip()
    if ext not in SUPPORTED_FORMATS:
        raise InvalidMeshError(
            f"unsupported mesh format {ext!r}; use one of: {', '.join(SUPPORTED_FORMATS)}"
        )
    return ext


def load_mesh(
    source: bytes | str | Path, file_type: str | None = None, max_vertices: int | None = None
) -> Mesh:
    """Read OBJ/OFF/PLY/STL/GLB from bytes (file_type required) or a path; validate and clean.

    max_vertices bounds the work a single upload can cause; larger meshes are refused.
    """
    if isinstance(source, (str, Path)):
        path = Path(source)
        file_type = detect_format(file_type or path.name)
        data = path.read_bytes()
    else:
        if file_type is None:
            raise InvalidMeshError("the mesh format is unknown: give a file name with an extension")
        file_type = detect_format(file_type)
        data = source
    if len(data) == 0:
        raise InvalidMeshError("the file is empty")
    vertices, faces = _parse(data, file_type)
    mesh = validate(vertices, faces)
    if max_vertices is not None and mesh.n_vertices > max_vertices:
        raise InvalidMeshError(
            f"the mesh has {mesh.n_vertices} vertices, more than the limit of {max_vertices}"
        )
    return clean(mesh)


def _parse(data: bytes, file_type: str) -> tuple[np.ndarray, np.ndarray]:
    if file_type == "obj":
        fast = _parse_obj_triangles(data)
        if fast is not None:
            return fast
    try:
        loaded: object = trimesh.load(io.BytesIO(data), file_type=file_type, process=False)
        if isinstance(loaded, trimesh.Scene):
            # GLB/PLY scenes: bake the node transforms and merge every triangle mesh
            geometry = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
            if not geometry and loaded.geometry:
                raise InvalidMeshError(f"the {file_type.upper()} file holds no triangle mesh")
            loaded = trimesh.util.concatenate(geometry) if geometry else None
        if loaded is None:
            raise InvalidMeshError("the mesh has no vertices")
        if isinstance(loaded, trimesh.PointCloud):
            raise InvalidMeshError("the mesh has no faces (a point cloud is not a surface)")
        if not isinstance(loaded, trimesh.Trimesh):
            raise InvalidMeshError(f"the {file_type.upper()} file holds no triangle mesh")
        vertices = np.asarray(loaded.vertices, dtype=np.float64)
        faces = np.asarray(loaded.faces, dtype=np.int64)
    except InvalidMeshError:
        raise
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise InvalidMeshError(f"could not read the file as {file_type.upper()}: {_short(exc)}") from exc
    return vertices, faces


_OBJ_V = re.compile(rb"^[ \t]*v[ \t]+([^\r\n]*)", re.M)
_OBJ_F = re.compile(rb"^[ \t]*f[ \t]+([^\r\n]*)", re.M)
_OBJ_SLASH = re.compile(rb"/[^ \t]*")


def _parse_obj_triangles(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """Fast path for the common OBJ: `v x y z [w|r g b]` and triangles `f a[/t][/n] ...`.

    About 3x faster than trimesh's reader on large files (one regex pass + a C number parser).
    Returns None (the caller then uses trimesh) for anything else: polygons, relative (negative)
    indices, odd vertex records, unparsable numbers, comments inside records.
    """
    try:
        v_lines = _OBJ_V.findall(data)
        f_lines = _OBJ_F.findall(data)
        if not v_lines or not f_lines:
            return None
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)  # a partial read warns: make it fail
            values = np.fromstring(b" ".join(v_lines), sep=" ")
        width = values.size // len(v_lines)
        if width not in (3, 4, 6, 7) or values.size != width * len(v_lines):
            return None
        face_text = b" ".join(f_lines)
        if b"/" in face_text:
            face_text = _OBJ_SLASH.sub(b"", face_text)
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)
            faces = np.fromstring(face_text, sep=" ", dtype=np.int64)
    except (ValueError, DeprecationWarning, AttributeError):  # AttributeError: a numpy without fromstring
        return None
    if faces.size != 3 * len(f_lines) or faces.size == 0 or faces.min() < 1:
        return None
    return values.reshape(-1, width)[:, :3].copy(), faces.reshape(-1, 3) - 1


def _short(exc: Exception) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return text[:200]


def validate(vertices: np.ndarray, faces: np.ndarray) -> Mesh:
    """Check raw arrays; raise InvalidMeshError with the first problem found."""
    vertices = np.asarray(vertices)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or vertices.shape[0] == 0:
        raise InvalidMeshError("the mesh has no vertices")
    if faces.size == 0:
        raise InvalidMeshError("the mesh has no faces (a point cloud is not a surface)")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise InvalidMeshError("faces must be triangles")
    if not np.all(np.isfinite(vertices)):
        raise InvalidMeshError("the mesh has non-finite vertex coordinates (NaN or infinity)")
    if faces.min() < 0 or faces.max() >= vertices.shape[0]:
        raise InvalidMeshError("a face points at a vertex that does not exist")
    if vertices.shape[0] < MIN_VERTICES:
        raise InvalidMeshError(f"the mesh has too few vertices ({vertices.shape[0]} < {MIN_VERTICES})")
    mesh = Mesh(vertices.astype(np.float64, copy=False), faces.astype(np.int64, copy=False))
    area = mesh.area()
    extent = float(np.ptp(mesh.vertices, axis=0).max())
    if not np.isfinite(area) or area <= 1e-12 * max(extent, 1e-300) ** 2 or extent == 0.0:
        raise InvalidMeshError("the mesh has zero total area (all faces are degenerate)")
    return mesh


def clean(mesh: Mesh, min_component_area_fraction: float = 0.01) -> Mesh:
    """Merge duplicate vertices, drop degenerate faces, small debris components and unreferenced vertices.

    Component policy: components holding less than `min_component_area_fraction` of the total area
    are debris (scan noise, stray triangles) and are dropped; the remaining components are all kept,
    and the spectrum treats their extra zero eigenvalues (see spectrum.first_nonzero).
    Vertices keep their input order (first occurrence of a merged group). Pure numpy: ~5x faster
    than the same steps through trimesh on a 160k-vertex mesh.
    """
    vertices, faces = merge_vertices(mesh.vertices, mesh.faces)
    areas = _face_areas(vertices, faces)
    scale = float(np.ptp(vertices, axis=0).max())
    keep = areas > 1e-14 * scale * scale
    faces, areas = faces[keep], areas[keep]
    first = unique_face_index(faces, len(vertices))
    faces, areas = faces[first], areas[first]
    if len(faces) < MIN_FACES:
        raise InvalidMeshError(f"the mesh has too few non-degenerate faces ({len(faces)} < {MIN_FACES})")
    labels = face_components(faces, len(vertices))
    comp_area = np.bincount(labels, weights=areas)
    keep = comp_area >= min_component_area_fraction * comp_area.sum()
    if not keep.all():
        faces = faces[keep[labels]]
    vertices, faces = drop_unreferenced(vertices, faces)
    out = Mesh(vertices, faces)
    if out.n_vertices < MIN_VERTICES or out.n_faces < MIN_FACES:
        raise InvalidMeshError("nothing usable is left once degenerate faces and debris are removed")
    return out


def _face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f,) float64 triangle areas."""
    a = vertices[faces[:, 0]]
    cross = np.cross(vertices[faces[:, 1]] - a, vertices[faces[:, 2]] - a)
    return 0.5 * np.sqrt(np.einsum("ij,ij->i", cross, cross))


def merge_vertices(vertices: np.ndarray, faces: np.ndarray, digits: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices equal after rounding to `digits` decimals; drop unreferenced ones.

    vertices : (n, 3) float64, faces : (f, 3) int64 -> (n', 3), (f, 3) with faces re-indexed.
    A 64-bit hash of each rounded row decides quickly that there are no duplicates (the usual
    case); only when two hashes collide does the exact row comparison run.
    """
    vertices, faces = drop_unreferenced(vertices, faces)
    keys = np.round(vertices * 10.0**digits).astype(np.int64)  # (n, 3)
    with np.errstate(over="ignore"):
        h = keys[:, 0] * np.int64(-7046029254386353131)
        h = (h ^ keys[:, 1]) * np.int64(0x100000001B3)
        h = (h ^ keys[:, 2]) * np.int64(-4417276706812531889)
    if np.unique(h).size == h.size:
        return vertices, faces
    from trimesh.grouping import unique_rows

    unique, inverse = unique_rows(keys, keep_order=True)
    return vertices[unique], inverse[faces].astype(np.int64)


def drop_unreferenced(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Remove vertices no face uses, keeping the order of the others."""
    n = len(vertices)
    used = np.zeros(n, dtype=bool)
    used[faces.ravel()] = True
    if used.all():
        return vertices, faces
    remap = np.cumsum(used) - 1
    return vertices[used], remap[faces]


def unique_face_index(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Sorted indices of the first occurrence of each face (faces equal as vertex sets)."""
    s = np.sort(faces, axis=1)
    if n_vertices < 2**20:  # the sorted triple packs exactly into one int64
        key = (s[:, 0] << 40) | (s[:, 1] << 20) | s[:, 2]
        _, first = np.unique(key, return_index=True)
    else:
        _, first = np.unique(s, axis=0, return_index=True)
    return np.sort(first)


def face_components(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(f,) int component label of each face (faces sharing a vertex are connected).

    Labels are numbered by first appearance in face order.
    """
    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    cols = np.concatenate([faces[:, 1], faces[:, 2]])
    graph = sp.csr_matrix((np.ones(rows.size, dtype=np.int8), (rows, cols)), shape=(n_vertices, n_vertices))
    _, labels = sp.csgraph.connected_components(graph, directed=False)
    face_labels = labels[faces[:, 0]]
    _, first, inverse = np.unique(face_labels, return_index=True, return_inverse=True)
    rank = np.empty(first.size, dtype=np.int64)
    rank[np.argsort(first)] = np.arange(first.size)
    return rank[inverse.ravel()]


def vertex_components(mesh: Mesh) -> np.ndarray:
    """(n,) int component label of each vertex."""
    n = mesh.n_vertices
    f = mesh.faces
    rows = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    cols = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    adj = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    _, labels = sp.csgraph.connected_components(adj, directed=False)
    return labels.astype(np.int64)
