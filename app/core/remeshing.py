"""Isotropic remeshing to the canonical resolution: the same surface, sampled evenly.

Subdivision and quadric decimation bring a mesh to about 1,000 vertices but keep its sampling: a
decimated mesh has its vertices bunched where the curvature is and long thin triangles on the flat
parts; a subdivided one keeps the pattern of its coarse parent. The Bag of Features counts vertices,
and the top of the spectrum (hence t_min) follows the smallest triangles, so two triangulations of one
surface gave different descriptors (without smoothing, SHREC'11 queried with a re-triangulated copy of
itself retrieves far worse: docs/results.md). Botsch & Kobbelt's remeshing (split long edges,
collapse short ones, flip towards valence 6, relax tangentially, project back onto the input) makes
every mesh an even sampling of its surface at one edge length, whatever it came from; vertices move
only along the surface. gpytoolbox implements it.

The edge length is chosen for `target_vertices` on the unit-area surface: an equilateral triangle
mesh with edge h has about 2 / (√3 h²) vertices per unit area.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from app.core.mesh import InvalidMeshError, Mesh, clean

ITERATIONS = 10  # Botsch & Kobbelt's split/collapse/flip/relax rounds; 5 leave visible valence defects
# a result outside these bounds (vertex count against the target, area against the input) means the
# remesher failed on this input (tiny parts, slivers it cannot resolve): the input is kept instead
COUNT_BAND = (0.5, 2.0)
# at ~1,000 vertices an even sampling cuts across fine relief (fingers, folds): CesiumMan and the
# realworld cat lose 6 % of their area, a multi-part GLB 13 %; more than this is a failed remesh
AREA_BAND = 0.2
SLIVER = 1e-3  # faces under this fraction of the target triangle's area are dropped after remeshing


def edge_length(area: float, target_vertices: int) -> float:
    """Target edge length h for `target_vertices` evenly spread over `area` (equilateral triangles)."""
    return float(np.sqrt(2.0 * area / (np.sqrt(3.0) * target_vertices)))


def isotropic_remesh(mesh: Mesh, target_vertices: int, iterations: int = ITERATIONS) -> Mesh:
    """Mesh -> an even triangulation of the same surface with about `target_vertices` vertices.

    mesh : a cleaned mesh (any resolution; meshes far above the target should be decimated first:
           the cost grows with the input size)
    Returns the input unchanged when target_vertices <= 0, or when the remesher's result is not a
    usable mesh of the same surface (see COUNT_BAND, AREA_BAND): remeshing is an improvement, never
    a reason to refuse a shape.
    """
    if target_vertices <= 0 or not remeshable(mesh):
        return mesh
    area = mesh.area()
    if not np.isfinite(area) or area <= 0:
        return mesh
    h = edge_length(area, target_vertices)
    # imported here, not with the module: remeshing is an option, and the package costs ~0.3 s to load
    with warnings.catch_warnings():  # its import uses deprecated numpy/scipy paths (0.3.8)
        warnings.simplefilter("ignore", DeprecationWarning)
        import gpytoolbox
    try:
        v, f = gpytoolbox.remesh_botsch(
            np.ascontiguousarray(mesh.vertices, dtype=np.float64),
            np.ascontiguousarray(mesh.faces, dtype=np.int32), i=iterations, h=h, project=True)
        raw = Mesh(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64))
        # near boundaries the remesher can leave folded slivers (a vertex of valence 2 whose two
        # faces have 1e-7 of the target area: SHREC'11 shark T104 re-triangulated); their vertices
        # get almost no mass and an eigenvalue of 1e13 that swamps the zero test of the spectrum
        keep = raw.face_areas() >= SLIVER * (np.sqrt(3.0) / 4.0) * h * h
        out = clean(Mesh(raw.vertices, raw.faces[keep]))
    except (InvalidMeshError, ValueError, RuntimeError):
        return mesh
    lo, hi = COUNT_BAND
    if not (lo * target_vertices <= out.n_vertices <= hi * target_vertices):
        return mesh
    if abs(out.area() - area) > AREA_BAND * area or not np.isfinite(out.vertices).all():
        return mesh
    return out


def remeshable(mesh: Mesh) -> bool:
    """True when the remesher can take the mesh: an oriented manifold. gpytoolbox's remesher
    assumes one and crashes the process (SIGSEGV) otherwise; four realworld files did: inconsistent
    winding (kenney__enemy-flying.glb, thingi10k 100827.stl) and pinched vertices
    (thingi10k 449816.stl, trimesh__wallhole.obj). Such meshes keep their sampling instead.

    Checked: no directed edge twice (consistent winding), at most two faces per edge, and every
    vertex's faces form one fan (corners joined across shared edges make one group per vertex).
    """
    faces = mesh.faces.astype(np.int64)
    n = np.int64(max(mesh.n_vertices, 1))
    tails = faces.ravel()  # half-edge 3f+p runs from corner 3f+p to corner 3f+(p+1)%3
    heads = faces[:, [1, 2, 0]].ravel()
    directed = tails * n + heads
    if np.unique(directed).size != directed.size:
        return False
    undirected = np.minimum(tails, heads) * n + np.maximum(tails, heads)
    order = np.argsort(undirected, kind="stable")
    keys = undirected[order]
    if keys.size > 2 and (keys[2:] == keys[:-2]).any():  # an edge with three faces or more
        return False
    # consistently oriented: a shared edge is a->b in one face and b->a in the other; join the
    # corners at a (and at b) across it
    pair = np.flatnonzero(keys[1:] == keys[:-1])
    h1, h2 = order[pair], order[pair + 1]
    nxt = (h1 // 3) * 3 + (h1 % 3 + 1) % 3  # the corner at h1's head
    nxt2 = (h2 // 3) * 3 + (h2 % 3 + 1) % 3
    corners = faces.size
    graph = sp.coo_matrix((np.ones(2 * h1.size), (np.concatenate([h1, nxt]), np.concatenate([nxt2, h2]))),
                          shape=(corners, corners))
    fans, _ = connected_components(graph, directed=False)
    return bool(fans == np.unique(faces).size)
