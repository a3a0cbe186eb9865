"""A cheap geometric fingerprint: a short vector that stays (nearly) the same for the same surface
whatever its vertex or face order, position, orientation, uniform scale, mirroring or triangulation.

It only picks candidates for the geometric verification (relate.py), so it must keep true variants
close and needs no more than to push most unrelated shapes away: a k-nearest-neighbour lookup in an
index of fingerprints (index.py) returns the few models worth verifying.
"""

from __future__ import annotations

import numpy as np

from app.core.meshdata import Mesh
from app.core.variants.surface import moments, sample_surface

FINGERPRINT_VERSION = 1  # stored with each fingerprint: a change of recipe makes old ones stale
DIM = 17
N_SAMPLES = 2048
QUANTILES = np.array([0.1, 0.3, 0.5, 0.7, 0.9])


def fingerprint(mesh: Mesh) -> np.ndarray:
    """(17,) float32, every entry dimensionless and of order 1:

    [0:2]   second-moment eigenvalue ratios l2/l1, l3/l1 of the surface (sorted, so order-free);
    [2]     4 pi trace / area (1 for a sphere; grows as the surface spreads);
    [3]     |volume| / area^1.5 (times 6 sqrt(pi), 1 for a sphere; 0 for a flat sheet);
    [4:7]   |third moment| along each principal axis / its spread (absolute: mirror-free);
    [7:12]  quantiles of the distance of the surface from its centroid / RMS radius;
    [12:17] quantiles of the distance between two surface points / RMS radius (the D2 distribution).
    """
    m = moments(mesh)
    values, axes = m.axes()
    values = np.maximum(values, 0.0)
    trace = float(values.sum())
    rms = np.sqrt(trace)
    points, _, _ = sample_surface(mesh, N_SAMPLES)
    local = (points - m.centroid) @ axes  # (n, 3) in the principal frame
    skew = np.abs((local**3).mean(axis=0)) / np.maximum(values, 1e-12 * trace) ** 1.5  # (3,)
    radial = np.quantile(np.linalg.norm(local, axis=1) / rms, QUANTILES)  # (5,)
    half = N_SAMPLES // 2
    pairs = np.linalg.norm(local[:half] - local[half:], axis=1) / rms  # (n/2,)
    d2 = np.quantile(pairs, QUANTILES)
    volume = abs(_signed_volume(mesh, m.centroid))
    out = np.concatenate([
        values[1:] / max(values[0], 1e-300),
        [4.0 * np.pi * trace / m.area, 6.0 * np.sqrt(np.pi) * volume / m.area**1.5],
        np.minimum(skew, 4.0) / 2.0,  # a flat axis can make the ratio explode: cap it
        radial,
        d2 / 2.0,
    ])
    return out.astype(np.float32)


def _signed_volume(mesh: Mesh, origin: np.ndarray) -> float:
    """Volume enclosed by the faces as seen from `origin` (exact for a closed, consistently wound
    surface; for an open one a translation-free number all the same)."""
    tri = mesh.vertices[mesh.faces] - origin  # (f, 3, 3)
    return float(np.einsum("fi,fi->f", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)
