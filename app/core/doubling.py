"""The double of an open surface: the surface glued to a mirror copy of itself along its free boundary.

Heat on a surface with a free boundary obeys Neumann's condition (no flux across the rim), and the Neumann
heat kernel is the double's folded back: K_P(x, y) = K_D(x, y) + K_D(x, y*), y* the mirror copy of y. So a
half-tube cut along a plane of symmetry (what a one-sided scan sees of a limb) has for double the whole
tube, and the double's eigenpairs read it as the tube it is half of (docs/partial.md, "Pieces a scanner
sees"). Intrinsic geometry only: the copy lies on the original (the same vertex positions), which the
cotangent Laplacian, built from edge lengths and angles, never looks at.
"""

from __future__ import annotations

import numpy as np

from app.core.partial import free_boundary

# a piece's rim (app.core.partial.rim_length: free boundary over √area) past which the pipeline solves on
# its double. A disc's is 2√π ≈ 3.5; a plane cut of a SHREC'11 model reads 1.1-4.8 (5 %-95 %), what a
# viewer sees of one 5.9-13.9, a whole model of any column at most 2.5 (docs/partial.md)
DOUBLE_RIM = 5.0


def doubled(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """vertices (n, 3), faces (f, 3) -> the double's vertices (n + m, 3) and faces (2f, 3).

    The first n vertices are the surface's own (its free-boundary vertices shared by both sheets), the
    next m the copies of its m other vertices; the copy's faces are flipped, so the double is oriented
    as the surface is. A closed surface has no free boundary: its double is two closed copies."""
    n = len(vertices)
    inner = np.flatnonzero(~free_boundary(faces, n))
    twin = np.arange(n)
    twin[inner] = n + np.arange(len(inner))
    return np.vstack([vertices, vertices[inner]]), np.vstack([faces, twin[faces][:, ::-1]])
