"""The canonical view of a thumbnail: the mesh turned into its principal axes, seen from the side that
shows the most silhouette, upright.

A fixed camera in the file's own coordinates drew z-up scans from below (horses legs-up). Here:
- the candidate viewing directions are the three principal axes (area-weighted covariance of the surface),
  and the one whose projection covers the largest area (2D convex hull of the projected vertices) wins;
- "up" is, of the two axes left, the one closer to the file's +y (the OBJ/glTF convention) or else +z
  (scans, STL, CAD), pointing the same way; with neither close, the less elongated axis, pointed against
  its long thin tail (legs, stems, handles hang down: the surface's third moment is negative upwards).
The result is a rotation (never a mirror), so the thumbnail renderer's 3/4 tilt still applies after it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

_HINT_COS = 0.9  # an axis within ~25 degrees of +y (or +z) is taken as the file's own up
_HULL_POINTS = 4000  # vertices sampled for the silhouette hulls (deterministic stride)
_ROUND = 6  # decimals kept of the trace-normalised covariance
_TIE = 0.01


def canonical_rotation(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(3, 3) rotation R (det +1): rows are the view's right, up and towards-the-camera axes, so
    `(v - centre) @ R.T` turns the mesh into that view. vertices (n, 3) float, faces (f, 3) int."""
    points, weights = _surface_samples(vertices, faces)
    centre = weights @ points
    spread = points - centre
    cov = (spread * weights[:, None]).T @ spread
    # rounded relative to its trace: near-equal variances (a sphere, a cube) then give the same axes
    # whatever the scale, position or face order, instead of an arbitrary basis of the eigenspace
    cov = np.round(cov / max(np.trace(cov), 1e-300), _ROUND)
    _, vecs = np.linalg.eigh(cov)
    axes = vecs.T[::-1]  # (3, 3) rows: principal axes, largest variance first
    sample = vertices[:: max(1, len(vertices) // _HULL_POINTS)] - centre
    areas = [_hull_area(sample, axes[[j for j in range(3) if j != i]]) for i in range(3)]
    # near-ties (within 1 %) go to the least elongated axis: stable, and the usual front view
    view = max(i for i in range(3) if areas[i] >= (1.0 - _TIE) * max(areas))
    rest = [i for i in range(3) if i != view]
    up = _up(axes[rest], spread, weights)
    toward = axes[view] * (1.0 if axes[view] @ np.array([0.0, 0.0, 1.0]) >= 0 else -1.0)
    toward = toward - (toward @ up) * up
    toward /= np.linalg.norm(toward)
    right = np.cross(up, toward)
    return np.stack([right, up, toward])


def _surface_samples(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Face centroids weighted by area (vertices, equally, when the surface has no area)."""
    v = np.asarray(vertices, np.float64)
    if len(faces):
        tri = v[faces]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        if area.sum() > 0:
            return tri.mean(axis=1), area / area.sum()
    return v, np.full(len(v), 1.0 / max(1, len(v)))


def _hull_area(points: np.ndarray, plane: np.ndarray) -> float:
    """Area of the 2D convex hull of `points` projected on the plane spanned by the two rows of `plane`."""
    try:
        return float(ConvexHull(points @ plane.T).volume)  # in 2D, qhull's "volume" is the area
    except (QhullError, ValueError):
        return 0.0


def _up(candidates: np.ndarray, spread: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Which of the two remaining axes points up, and which way (see the module's docstring)."""
    for hint in (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])):
        cos = candidates @ hint
        best = int(np.argmax(np.abs(cos)))
        if abs(cos[best]) >= _HINT_COS:
            return candidates[best] * np.sign(cos[best])
    axis = candidates[1]  # the less elongated of the two
    skew = weights @ (spread @ axis) ** 3
    return axis * (-1.0 if skew > 0 else 1.0)
