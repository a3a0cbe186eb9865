"""Validate raw arrays and clean them into a usable mesh: weld, drop degenerate faces and debris.

Every tolerance here is relative to the mesh's own size (its bounding box), so a mesh in metres, in
nanometres (1e-9) or in astronomical units (1e12), or translated far from the origin, cleans to the
same topology.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from app.core.meshdata import MIN_FACES, MIN_VERTICES, InvalidMeshError, Mesh

# Past these, areas over- or underflow in float64: a triangle's area is the norm of a cross product,
# computed through its square (~ edge^4), so 1e100 coordinates gave infinite areas and a 1e-80 mesh lost
# faces to underflow (called degenerate). Within 1e-70..1e70 the squares stay normal doubles even for
# the 2M-vertex limit's short edges (extent / 1400).
MAX_COORDINATE = 1e70
MIN_EXTENT = 1e-70
WELD_TOLERANCE = 1e-8  # fraction of the largest bounding-box side
DEGENERATE_AREA = 1e-14  # fraction of the squared largest side
DEBRIS_FRACTION = 0.01  # fraction of the largest component's area


def validate(vertices: np.ndarray, faces: np.ndarray) -> Mesh:
    """Check raw arrays (vertices (n, 3) float, faces (f, 3) int); raise InvalidMeshError with the first
    problem found, else return them as a Mesh."""
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
    mask = np.zeros(mesh.n_vertices, dtype=bool)
    mask[mesh.faces.ravel()] = True
    used = mesh.vertices if mask.all() else mesh.vertices[mask]  # stray points must not set the scale
    biggest = float(np.abs(used).max())
    if biggest > MAX_COORDINATE:
        raise InvalidMeshError(
            f"the coordinates are too large (up to {biggest:.3g}; at most {MAX_COORDINATE:g}):"
            " scale the model down before exporting it"
        )
    lo = used.min(axis=0)
    extent = float((used.max(axis=0) - lo).max())
    if extent == 0.0:
        raise InvalidMeshError("the mesh has zero total area (all faces are degenerate)")
    if extent < MIN_EXTENT:
        raise InvalidMeshError(
            f"the mesh is too small (it spans {extent:.3g}; at least {MIN_EXTENT:g}):"
            " scale the model up before exporting it"
        )
    # the area test in units of the mesh's own size: scale invariant; within these bounds on the
    # coordinates, areas neither overflow nor underflow in float64
    if not float(_face_areas(mesh.vertices, mesh.faces).sum()) > 1e-12 * extent * extent:
        raise InvalidMeshError("the mesh has zero total area (all faces are degenerate)")
    return mesh


def clean(mesh: Mesh, min_component_area_fraction: float = DEBRIS_FRACTION) -> Mesh:
    """Weld duplicate positions, drop degenerate and repeated faces, debris, and unreferenced vertices.

    Welding ignores normals and UVs (only positions count), so the seams that OBJ and glTF exports
    duplicate are closed. Tolerances are relative to the bounding box (see merge_vertices).

    Components policy (faces sharing a vertex are one component): a component whose area is less than
    `min_component_area_fraction` (1 %) of the *largest* component's area is debris (scan noise, stray
    triangles, a screw beside a chair) and is dropped; every other component is kept, however many
    there are, so a shape made of many equal parts (an instanced GLB, a plate of printed pieces)
    keeps all of them. The spectrum handles the extra zero eigenvalues (spectrum.first_nonzero).
    A triangle soup, where no kept component has MIN_FACES faces (e.g. 100 separate triangles), has
    no surface for the Laplace-Beltrami operator to act on and is refused with a message saying so.
    Vertices keep their input order (first occurrence of a welded group).
    """
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:  # e.g. a resampling that kept nothing
        raise InvalidMeshError("the mesh has no faces left to describe")
    vertices, faces = merge_vertices(mesh.vertices, mesh.faces)
    areas = _face_areas(vertices, faces)
    side = float(np.ptp(vertices, axis=0).max())
    keep = areas > DEGENERATE_AREA * side * side
    faces, areas = faces[keep], areas[keep]
    first = unique_face_index(faces, len(vertices))
    faces, areas = faces[first], areas[first]
    if len(faces) < MIN_FACES:
        raise InvalidMeshError(f"the mesh has too few non-degenerate faces ({len(faces)} < {MIN_FACES})")
    labels = face_components(faces, len(vertices))
    comp_area = np.bincount(labels, weights=areas)
    keep = comp_area >= min_component_area_fraction * comp_area.max()
    comp_faces = np.bincount(labels)
    if comp_faces[keep].max() < MIN_FACES:
        largest = int(comp_faces.max())
        size = "a single face each" if largest == 1 else f"at most {largest} faces each"
        raise InvalidMeshError(
            f"the mesh is a triangle soup: its {len(faces)} faces form {comp_area.size} separate pieces"
            f" ({size}), with no surface joining them; export it as a connected (welded) surface"
        )
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


def merge_vertices(
    vertices: np.ndarray, faces: np.ndarray, tolerance: float = WELD_TOLERANCE
) -> tuple[np.ndarray, np.ndarray]:
    """Weld vertices whose positions agree within `tolerance` x the largest bounding-box side.

    vertices : (n, 3) float64, faces : (f, 3) int64 -> (n', 3), (f, 3) with faces re-indexed; vertices
    no face uses are dropped. Positions are snapped to a grid anchored at the bounding box's corner
    (translation and scale invariant: 1e8 cells per side fit int64 whatever the units). Copies of one
    vertex are bit-identical and always meet; two distinct positions closer than the tolerance meet
    unless a grid line falls between them. Cells are grouped by a 64-bit hash of their coordinates (one
    1-D sort); the grouping is then checked exactly, and a hash collision falls back to a row sort.
    """
    vertices, faces = drop_unreferenced(vertices, faces)
    lo = vertices.min(axis=0)
    side = float((vertices.max(axis=0) - lo).max())
    cell = tolerance * side if side > 0 else 1.0
    grid = vertices - lo  # in place from here: this runs on every raw corner of a large STL
    grid /= cell
    grid += 0.5
    keys = np.floor(grid, out=grid).astype(np.int64)  # (n, 3), each in [0, 1e8]
    del grid
    with np.errstate(over="ignore"):
        h = keys[:, 0] * np.int64(-7046029254386353131)
        h = (h ^ keys[:, 1]) * np.int64(0x100000001B3)
        h = (h ^ keys[:, 2]) * np.int64(-4417276706812531889)
    _, first, inverse = np.unique(h, return_index=True, return_inverse=True)
    if first.size == h.size:  # the usual case: no duplicates
        return vertices, faces
    inverse = inverse.ravel()
    if not np.array_equal(keys[first][inverse], keys):  # two cells share a hash (~n^2 / 2^64): be exact
        first, inverse = _groups(keys)
    unique, inverse = _in_input_order(first, inverse)
    return vertices[unique], inverse[faces]


def _groups(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """keys (n, k) int64 -> first (g,) index of each distinct row, inverse (n,) group of each row."""
    order = np.lexsort(keys.T[::-1])  # stable: the first row of each run is the smallest index
    sorted_keys = keys[order]
    starts = np.ones(len(keys), dtype=bool)
    starts[1:] = (sorted_keys[1:] != sorted_keys[:-1]).any(axis=1)
    inverse = np.empty(len(keys), dtype=np.int64)
    inverse[order] = np.cumsum(starts) - 1
    return order[starts], inverse


def _in_input_order(first: np.ndarray, inverse: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Renumber groups by first appearance -> (sorted first indices, inverse in the new numbering)."""
    rank = np.empty(first.size, dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(first.size)
    return np.sort(first), rank[inverse]


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
    if n_vertices <= 2**21:  # the sorted triple packs exactly into one int64 (3 x 21 bits)
        key = (s[:, 0] << 42) | (s[:, 1] << 21) | s[:, 2]
        _, first = np.unique(key, return_index=True)
    else:
        first = _groups(s)[0]
    return np.sort(first)


def edge_uses(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """faces (f, 3) int -> (edge (3f,), uses (3f,)): for each face-edge row (row // 3 is its face) the
    id of its undirected edge and how many faces use that edge."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1).astype(np.int64)  # (3f, 2)
    # one int64 key per edge (a * n + b is exact below 3e9 vertices): a 1-D unique is ~5x faster
    # than np.unique(axis=0) on the 11M edge rows of a 2M-vertex mesh
    keys = edges[:, 0] * (int(faces.max(initial=0)) + 1) + edges[:, 1]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    return inverse, counts[inverse]


def nonmanifold_faces(faces: np.ndarray) -> np.ndarray:
    """faces (f, 3) int -> (f,) bool: the face has an edge shared by more than two faces."""
    return np.asarray((edge_uses(faces)[1] > 2).reshape(-1, 3).any(axis=1))


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
