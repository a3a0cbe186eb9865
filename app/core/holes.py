"""Closing the small holes of an open surface: scans come with holes where the scanner saw nothing.

A hole is a boundary loop. The Laplace–Beltrami operator treats it as an edge of the surface (Neumann
condition): heat does not cross it, so the HKS of every vertex within √t of the rim rises and the large
time scales see another shape. Two scans of one object rarely have the same holes, so descriptors
computed with the holes open depend on where the scanner looked. Each small hole is closed with a fan
around the centroid of its rim: the patch is flat, not the surface that was there, but it gives heat a
path across the gap of about the right length, which is what the spectrum sees.

A large loop is part of the shape, not a gap (the rim of a cup, the edge of a sheet, the outline of a
flat part): a loop is closed only if its cap adds at most `max_area_fraction` of its piece's area.
Loops through a pinched vertex (a vertex on two boundary loops, or on a loop twice) are left open:
their order along the rim is not defined.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from app.core.cleaning import vertex_components
from app.core.mesh import Mesh

MIN_CAP_FACE = 0.01  # a cap triangle under this fraction of the mean face area is a sliver


def boundary_loops(faces: np.ndarray, n_vertices: int) -> list[np.ndarray]:
    """Closed boundary loops, each (L,) int64 vertex indices in the order of the faces' winding.

    A boundary edge is an edge of exactly one face; its direction (a -> b) is the one in that face.
    Loops whose vertices do not each have exactly one boundary edge in and one out are skipped.
    faces (f, 3) int.
    """
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)  # (3f, 2)
    undirected = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(undirected, axis=0, return_inverse=True, return_counts=True)
    edges = directed[counts[inverse.ravel()] == 1]  # (b, 2) directed boundary edges
    if len(edges) == 0:
        return []
    out_deg = np.bincount(edges[:, 0], minlength=n_vertices)
    in_deg = np.bincount(edges[:, 1], minlength=n_vertices)
    graph = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n_vertices, n_vertices))
    _, component = sp.csgraph.connected_components(graph, directed=True, connection="weak")
    bad = np.unique(component[(out_deg != in_deg) | (out_deg > 1)])
    following = np.full(n_vertices, -1, dtype=np.int64)
    simple = (out_deg == 1) & ~np.isin(component, bad)
    following[edges[:, 0]] = edges[:, 1]
    loops = []
    seen = np.zeros(n_vertices, dtype=bool)
    for start in np.flatnonzero(simple):
        if seen[start]:
            continue
        loop = [start]
        seen[start] = True
        v = following[start]
        while v != start:  # each vertex of a simple component has one successor: the walk closes
            loop.append(v)
            seen[v] = True
            v = following[v]
        if len(loop) >= 3:
            loops.append(np.asarray(loop, dtype=np.int64))
    return loops


def fill_holes(mesh: Mesh, max_area_fraction: float) -> tuple[Mesh, int]:
    """(mesh with its small holes closed, number of holes closed).

    Each loop whose centroid fan has an area <= max_area_fraction x the area of the loop's own
    connected piece gets one new vertex (the rim's centroid) and one triangle per rim edge, wound like
    the faces beside it. The piece's area, not the whole mesh's: a small open part beside a big closed
    one (a sheet, a tube) keeps its outline.
    A loop is left as it is when any triangle of its fan would be a sliver (under MIN_CAP_FACE x the
    mesh's mean face area): a slit, a puncture where decimation collapsed a face to a point and cleaning
    removed it (its three vertices ~1e-8 apart), or a non-convex rim whose centroid falls on the line of
    one of its edges. Such a triangle gives a vertex (almost) without area, which the mass matrix cannot
    take, or a cotangent weight of ~1e307. Welding punctures shut instead was measured and retrieved
    worse across triangulations (docs/results.md).
    max_area_fraction <= 0 returns the mesh unchanged. vertices (n, 3) -> (n + closed, 3).
    """
    if max_area_fraction <= 0:
        return mesh, 0
    v, f = mesh.vertices, mesh.faces
    loops = boundary_loops(f, len(v))
    if not loops:
        return mesh, 0
    face_areas = mesh.face_areas()
    sliver = MIN_CAP_FACE * float(face_areas.mean())
    piece = vertex_components(mesh)  # (n,) connected piece of each vertex
    piece_area = np.bincount(piece[f[:, 0]], weights=face_areas, minlength=piece.max() + 1)  # per piece
    new_vertices: list[np.ndarray] = []
    new_faces: list[np.ndarray] = []
    for loop in loops:
        centre = v[loop].mean(axis=0)
        rim = np.stack([loop, np.roll(loop, -1)], axis=1)  # (L, 2): edge a -> b of the rim
        fan = 0.5 * np.linalg.norm(np.cross(v[rim[:, 0]] - centre, v[rim[:, 1]] - centre), axis=1)  # (L,)
        if fan.min() < sliver or fan.sum() > max_area_fraction * piece_area[piece[loop[0]]]:
            continue
        index = len(v) + len(new_vertices)
        new_vertices.append(centre)
        # the face beside a rim edge runs a -> b; the cap's triangle runs b -> a so the two agree
        new_faces.append(np.column_stack([rim[:, 1], rim[:, 0], np.full(len(rim), index)]))
    if not new_vertices:
        return mesh, 0
    return Mesh(np.vstack([v, np.asarray(new_vertices)]), np.vstack([f, *new_faces])), len(new_vertices)

