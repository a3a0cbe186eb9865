"""Small meshes the variants tests share: random convex hulls (no symmetry, so a mirror image is not a
rotation of one) and plates of several meshes side by side."""

from __future__ import annotations

import numpy as np
import trimesh

from app.core.mesh import Mesh


def hull_trimesh(seed: int, n: int = 80, scale: float = 1.0) -> trimesh.Trimesh:
    """The convex hull of n Gaussian points stretched 1 : 0.6 : 0.35, times `scale`."""
    points = np.random.default_rng(seed).normal(size=(n, 3)) * [1.0, 0.6, 0.35]
    tm = trimesh.convex.convex_hull(points)
    tm.apply_scale(scale)
    return tm


def hull(seed: int, n: int = 80) -> Mesh:
    """hull_trimesh as a core Mesh: vertices (v, 3) float64, faces (f, 3) int64."""
    tm = hull_trimesh(seed, n)
    return Mesh(np.asarray(tm.vertices, float), np.asarray(tm.faces, np.int64))


def plate(meshes: list[Mesh]) -> Mesh:
    """The meshes side by side along x, 3 of their largest extents apart, as one mesh."""
    step = 3.0 * max(float(np.ptp(m.vertices, axis=0).max()) for m in meshes)
    v = [m.vertices + [i * step, 0, 0] for i, m in enumerate(meshes)]
    offsets = np.cumsum([0] + [m.n_vertices for m in meshes[:-1]])
    return Mesh(np.vstack(v), np.vstack([m.faces + o for m, o in zip(meshes, offsets, strict=True)]))
