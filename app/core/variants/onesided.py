"""One-sided evidence for a re-triangulation: one mesh lies on the other's surface.

A decimated or remeshed copy is coarser than its original, and its *vertices* lie on (or very near) the
original surface, while its flat triangles cut across the curved original by an amount that grows with
the triangle size; thin parts it dropped leave some of the original uncovered. A symmetric mean distance
mixes the two and, for a 25-vertex copy of a 250-vertex mesh, reads like two different members of one
class. Here the test is one-sided and measured in the lying mesh's own resolution (its mean edge length
`e`, capped at RESOLUTION_CAP of the diagonal so that a few huge flat triangles buy no slack):

- the lying mesh's vertices: 99 % within VERTEX_TOL e of the other surface, all within VERTEX_MAX e;
- the other surface is covered: 90 % of its area within COVER_TOL e of the lying mesh.

Two poses of one object (a laptop opened further) or two members of a class fail: some of their
vertices are several edge lengths off the other surface, or a large part of it is far from them.
Both directions are tried; the better one is the evidence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.meshdata import Mesh

VERTEX_TOL = 0.4  # 99 % of the lying mesh's vertices within 0.4 of its mean edge of the other surface
VERTEX_MAX = 0.6  # ... and every one within 0.6
COVER_TOL = 0.6  # 90 % of the other surface within 0.6 mean edges of the lying mesh
RESOLUTION_CAP = 0.2  # the edge length used is at most 20 % of the diagonal
MAX_VERTICES = 4096  # vertices measured per mesh (an even stride through larger meshes)


@dataclass(frozen=True)
class LiesOn:
    """Evidence that one mesh lies on the other, all lengths relative to the stored mesh's diagonal.

    a_on_b     : True when `a` (the query) is the lying mesh, False when `b` is
    resolution : the lying mesh's mean edge length (capped)
    vertex_gap : 99 % quantile of its vertices' distances to the other surface
    uncovered  : 90 % quantile of the other surface's distances to it
    margin     : max(vertex_gap / (VERTEX_TOL e), largest vertex distance / (VERTEX_MAX e),
                 uncovered / (COVER_TOL e)); below 1 the test is passed
    """

    a_on_b: bool
    resolution: float
    vertex_gap: float
    uncovered: float
    margin: float


def mean_edge(mesh: Mesh) -> float:
    """Mean length of the triangles' sides (each interior edge counted twice, which a mean ignores)."""
    tri = mesh.vertices[mesh.faces]  # (f, 3, 3)
    return float(np.linalg.norm(tri - tri[:, [1, 2, 0]], axis=2).mean())


def vertex_subset(mesh: Mesh) -> np.ndarray:
    """(<= MAX_VERTICES, 3) the vertices that some face uses, an even stride through a large mesh."""
    used = mesh.vertices[np.unique(mesh.faces)]
    return used[:: max(1, -(-len(used) // MAX_VERTICES))]


def side(vertex_dist: np.ndarray, other_dist: np.ndarray, edge: float) -> tuple[float, float, float, float]:
    """(resolution, vertex_gap, uncovered, margin) for one direction. vertex_dist (n,): the lying
    mesh's vertices to the other surface; other_dist (m,): the other's surface samples to the lying
    mesh; edge: the lying mesh's mean edge; all in one unit (relative to the diagonal)."""
    e = max(min(edge, RESOLUTION_CAP), 1e-12)
    gap = float(np.quantile(vertex_dist, 0.99))
    uncovered = float(np.quantile(other_dist, 0.9))
    worst = float(vertex_dist.max())
    margin = max(gap / (VERTEX_TOL * e), worst / (VERTEX_MAX * e), uncovered / (COVER_TOL * e))
    return e, gap, uncovered, margin


def lies_on(
    a_vertex_dist: np.ndarray, b_sample_dist: np.ndarray, a_edge: float,
    b_vertex_dist: np.ndarray, a_sample_dist: np.ndarray, b_edge: float,
) -> LiesOn:
    """The better of "a lies on b" and "b lies on a". a_vertex_dist (n,): a's vertices to b's surface;
    b_sample_dist (m,): b's surface samples to a's surface; a_edge: a's mean edge; likewise for b.
    Everything relative to one length (the diagonal of b)."""
    a_side = side(a_vertex_dist, b_sample_dist, a_edge)
    b_side = side(b_vertex_dist, a_sample_dist, b_edge)
    if a_side[3] <= b_side[3]:
        return LiesOn(True, *a_side)
    return LiesOn(False, *b_side)
