"""A cheap geometric fingerprint: a short vector that stays (nearly) the same for the same surface
whatever its vertex or face order, position, orientation, uniform scale, mirroring or triangulation.

It only picks candidates for the geometric verification (relate.py), so it must keep true variants
close and needs no more than to push most unrelated shapes away: a k-nearest-neighbour lookup in an
index of fingerprints (index.py) returns the few models worth verifying.
"""

from __future__ import annotations

import numpy as np

from app.core.meshdata import Mesh
from app.core.variants.surface import Faces, Moments, faces_of, moments, sample_surface

FINGERPRINT_VERSION = 1  # stored with each fingerprint: a change of recipe makes old ones stale
DIM = 17
N_SAMPLES = 4096
QUANTILES = np.array([0.1, 0.3, 0.5, 0.7, 0.9])


def fingerprint(mesh: Mesh, faces: Faces | None = None, m: Moments | None = None) -> np.ndarray:
    """(17,) float32, every entry dimensionless and of order 1 (`faces`, `m`: the mesh's per-face
    arrays and moments when already at hand):

    [0:2]   second-moment eigenvalue ratios l2/l1, l3/l1 of the surface (sorted, so order-free);
    [2]     4 pi trace / area (1 for a sphere; grows as the surface spreads);
    [3]     |volume| / area^1.5 (times 6 sqrt(pi), 1 for a sphere; 0 for a flat sheet);
    [4:7]   |third moment| along each principal axis / its spread (exact; absolute: mirror-free);
    [7:12]  quantiles of the distance of the surface from its centroid / RMS radius;
    [12:17] quantiles of the distance between two surface points / RMS radius (the D2 distribution).
    """
    faces = faces or faces_of(mesh)
    m = m or moments(mesh, faces)
    values, axes = m.axes()
    values = np.maximum(values, 0.0)
    trace = float(values.sum())
    rms = np.sqrt(trace)
    skew = np.abs(_third_moments(faces, m, axes)) / np.maximum(values, 1e-12 * trace) ** 1.5  # (3,)
    points, _, _ = sample_surface(mesh, N_SAMPLES, faces=faces)
    local = (points - m.centroid) @ axes  # (n, 3) in the principal frame
    radial = np.quantile(np.linalg.norm(local, axis=1) / rms, QUANTILES)  # (5,)
    half = N_SAMPLES // 2
    pairs = np.linalg.norm(local[:half] - local[half:], axis=1) / rms  # (n/2,)
    d2 = np.quantile(pairs, QUANTILES)
    volume = abs(_signed_volume(faces, m.centroid))
    out = np.concatenate([
        values[1:] / max(values[0], 1e-300),
        [4.0 * np.pi * trace / m.area, 6.0 * np.sqrt(np.pi) * volume / m.area**1.5],
        np.minimum(skew, 4.0) / 2.0,  # a flat axis can make the ratio explode: cap it
        radial,
        d2 / 2.0,
    ])
    return out.astype(np.float32)


def _third_moments(faces: Faces, m: Moments, axes: np.ndarray) -> np.ndarray:
    """(3,) exact (1/A) integral of u^3 dA along each principal axis. With barycentric integrals
    (integral of l1^a l2^b l3^c = 2A a! b! c! / (a+b+c+2)!) a triangle gives
    A/10 (sum u_i^3 + sum_{i != j} u_i^2 u_j + u_1 u_2 u_3) for corner values u_i; with the power
    sums s_k = sum u_i^k that is A/10 (s1^3 + 3 s1 s2 + 2 s3) / 6."""
    f = len(faces.area)
    u = ((faces.tri.reshape(-1, 3) - m.centroid) @ axes).reshape(f, 3, 3)  # (f, 3 corners, 3 axes)
    u0, u1, u2 = np.ascontiguousarray(u.transpose(1, 0, 2))  # (f, 3) each, one per corner
    s1 = u0 + u1 + u2
    s2 = u0 * u0 + u1 * u1 + u2 * u2
    s3 = u0 * u0 * u0 + u1 * u1 * u1 + u2 * u2 * u2
    cubic = (s1 * s1 * s1 + 3.0 * s1 * s2 + 2.0 * s3) / 6.0  # (f, 3)
    return faces.area @ cubic / (10.0 * m.area)


def _signed_volume(faces: Faces, origin: np.ndarray) -> float:
    """Volume enclosed by the faces as seen from `origin` (exact for a closed, consistently wound
    surface; for an open one a translation-free number all the same): the sum of a . (b - a) x (c - a)
    / 6 = a . b x c / 6 over the faces, corners relative to `origin`."""
    return float(np.einsum("fi,fi->f", faces.tri[:, 0] - origin, faces.cross).sum() / 6.0)
