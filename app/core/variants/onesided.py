"""One-sided evidence for a re-triangulation: one mesh lies on the other's surface.

A decimated or remeshed copy is coarser than its original, and its *vertices* lie on (or very near) the
original surface, while its flat triangles cut across the curved original by an amount that grows with
the triangle size; thin parts it dropped leave some of the original uncovered. A symmetric mean distance
mixes the two and, for a 25-vertex copy of a 250-vertex mesh, reads like two different members of one
class. Here the test is one-sided, with tolerances that grow with how much coarser the lying mesh is:

- it has at least MIN_VERTICES vertices, and its slack `s` is its mean edge length (at most
  RESOLUTION_CAP of the diagonal, so that a few huge flat triangles buy nothing) times its coarsening:
  0 when it is no coarser than the other, rising to 1 when its edges are FULL_COARSENING times as long
  (a decimation to 10 % is about 3 times);
- 99 % of its vertices within max(VERTEX_FLOOR, VERTEX_TOL s) of the other surface, every one within
  max(VERTEX_MAX_FLOOR, VERTEX_MAX s): a remesh at the same resolution must lie on the surface;
- the other surface covered: 90 % of its area within max(COVER_FLOOR, COVER_TOL s) of the lying mesh
  (a thin part dropped is a small fraction of the area, however far it reaches).

Two poses of one object (a laptop opened further), two members of a class, two coarse blobs at one
resolution fail: some of their vertices are off the other surface by several per cent of the diagonal,
or a large part of it is far from them. Both directions are tried; the better one is the evidence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.meshdata import Mesh

VERTEX_TOL = 0.3  # 99 % of the lying mesh's vertices within 0.3 slack of the other surface ...
VERTEX_FLOOR = 0.015  # ... or 1.5 % of the diagonal
VERTEX_MAX = 0.6  # every vertex within 0.6 slack ...
VERTEX_MAX_FLOOR = 0.02  # ... or 2 %
COVER_TOL = 0.5  # 90 % of the other surface within 0.5 slack of the lying mesh ...
COVER_FLOOR = 0.03  # ... or 3 %
RESOLUTION_CAP = 0.15  # the edge length used is at most 15 % of the diagonal
MIN_VERTICES = 20  # a mesh of fewer vertices (a box) is too coarse to be said to lie on anything
FULL_COARSENING = 2.0  # edges this many times the other's: the whole edge length is slack
MAX_VERTICES = 4096  # vertices measured per mesh (an even stride through larger meshes)


@dataclass(frozen=True)
class LiesOn:
    """Evidence that one mesh lies on the other, all lengths relative to the stored mesh's diagonal.

    a_on_b     : True when `a` (the query) is the lying mesh, False when `b` is
    resolution : the lying mesh's mean edge length
    slack      : the length its tolerances grow with (module docstring)
    vertex_gap : 99 % quantile of its vertices' distances to the other surface
    uncovered  : 90 % quantile of the other surface's distances to it
    margin     : the largest of the three measures over its tolerance; below 1 the test is passed
    """

    a_on_b: bool
    resolution: float
    slack: float
    vertex_gap: float
    uncovered: float
    margin: float


def mean_edge(mesh: Mesh, tri: np.ndarray | None = None) -> float:
    """Mean length of the triangles' sides (each interior edge counted twice, which a mean ignores);
    `tri` (f, 3, 3): the corners when already at hand."""
    tri = mesh.vertices[mesh.faces] if tri is None else tri
    d = tri - tri[:, [1, 2, 0]]  # (f, 3, 3) the three sides
    return float(np.sqrt(np.einsum("fci,fci->fc", d, d)).mean())


def vertex_subset(mesh: Mesh, limit: int | None = None, used: np.ndarray | None = None) -> np.ndarray:
    """(<= limit or MAX_VERTICES, 3) the vertices that some face uses, an even stride through a large
    mesh; `used` (u, 3): those vertices when already at hand."""
    if used is None:
        used = mesh.vertices[np.unique(mesh.faces)]
    return used[:: max(1, -(-len(used) // (limit or MAX_VERTICES)))]


def slack(edge: float, other_edge: float) -> float:
    """The lying mesh's mean edge (capped) times its coarsening against the other's mean edge."""
    coarsening = (edge / max(other_edge, 1e-300) - 1.0) / (FULL_COARSENING - 1.0)
    return min(edge, RESOLUTION_CAP) * float(np.clip(coarsening, 0.0, 1.0))


def side(
    vertex_dist: np.ndarray, other_dist: np.ndarray, edge: float, other_edge: float
) -> tuple[float, float, float, float, float]:
    """(resolution, slack, vertex_gap, uncovered, margin) for one direction. vertex_dist (n,): the
    lying mesh's vertices to the other surface; other_dist (m,): the other's surface samples to the
    lying mesh; edge, other_edge: the two mean edges; all in one unit (relative to the diagonal).
    The margin is infinite for a lying mesh of fewer than MIN_VERTICES vertices."""
    s = slack(edge, other_edge)
    gap = float(np.quantile(vertex_dist, 0.99))
    worst = float(vertex_dist.max())
    uncovered = float(np.quantile(other_dist, 0.9))
    margin = max(gap / max(VERTEX_FLOOR, VERTEX_TOL * s), worst / max(VERTEX_MAX_FLOOR, VERTEX_MAX * s),
                 uncovered / max(COVER_FLOOR, COVER_TOL * s))
    if len(vertex_dist) < MIN_VERTICES:
        margin = float("inf")
    return edge, s, gap, uncovered, margin


def cover_margin(other_dist: np.ndarray, edge: float, other_edge: float) -> float:
    """side()'s coverage term alone, a lower bound of its margin (the vertex terms can only raise it):
    other_dist (m,) the other's surface samples to the lying mesh, relative to the diagonal."""
    return float(np.quantile(other_dist, 0.9)) / max(COVER_FLOOR, COVER_TOL * slack(edge, other_edge))


def lies_on(
    a_vertex_dist: np.ndarray, b_sample_dist: np.ndarray, a_edge: float,
    b_vertex_dist: np.ndarray, a_sample_dist: np.ndarray, b_edge: float,
) -> LiesOn:
    """The better of "a lies on b" and "b lies on a". a_vertex_dist (n,): a's vertices to b's surface;
    b_sample_dist (m,): b's surface samples to a's surface; a_edge: a's mean edge; likewise for b.
    Everything relative to one length (the diagonal of b)."""
    a_side = side(a_vertex_dist, b_sample_dist, a_edge, b_edge)
    b_side = side(b_vertex_dist, a_sample_dist, b_edge, a_edge)
    if a_side[4] <= b_side[4]:
        return LiesOn(True, *a_side)
    return LiesOn(False, *b_side)
