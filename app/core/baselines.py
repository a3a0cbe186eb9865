"""Two peer descriptors, measured in the same harness as HKS-BoF so the figures stand side by side.

Shape-DNA (Reuter, Wolter & Peinecke, "Laplace–Beltrami spectra as 'Shape-DNA' of surfaces and
solids", CAD 2006; Reuter's entry in the SHREC'11 non-rigid track): the beginning of the
Laplace–Beltrami spectrum. Eigenvalues scale as 1/s² with the surface, so they are normalised by the
area A (λ_i · A); by Weyl's law λ_i · A ≈ 4π i, so dividing by i gives every entry the same order of
magnitude and lets a plain Euclidean distance weigh the first and the 30th eigenvalue alike.
Isometry-invariant (intrinsic), hence invariant to rotation, translation and, after the area
normalisation, uniform scale.

D2 shape distribution (Osada, Funkhouser, Chazelle & Dobkin, "Shape distributions", ACM TOG 2002):
the histogram of Euclidean distances between random pairs of points drawn uniformly on the surface,
with distances divided by their mean (scale invariance), compared with the L1 distance between
histograms. Rigid-invariant but not bending-invariant: a useful floor for a non-rigid benchmark.

Pure numpy (the spectrum reuses the core's Laplacian and eigen-solver); seeds make every result
reproducible.
"""

from __future__ import annotations

import numpy as np

from app.core.laplacian import cotangent_laplacian
from app.core.mesh import Mesh
from app.core.spectrum import first_nonzero, smallest_eigenpairs

SHAPE_DNA_COUNT = 30
D2_PAIRS = 1 << 15
D2_BINS = 64
D2_MAX_RATIO = 4.0  # distance / mean distance; larger ratios (rare) fall into the last bin


def shape_dna(eigenvalues: np.ndarray, area: float = 1.0, count: int = SHAPE_DNA_COUNT) -> np.ndarray:
    """(k,) ascending Laplace–Beltrami eigenvalues of a surface of area `area` -> (count,) λ_i·A / i.

    The zero eigenvalues (one per connected component) are skipped: λ_1 here is the first
    non-zero one. The core's ShapeDescription.eigenvalues belong to a unit-area mesh (area=1).
    """
    lam = np.sort(np.asarray(eigenvalues, dtype=np.float64))
    lam = lam[first_nonzero(lam):]
    if lam.size < count:
        raise ValueError(f"Shape-DNA needs {count} non-zero eigenvalues, the spectrum has {lam.size}")
    return lam[:count] * area / np.arange(1, count + 1)


def shape_dna_of_mesh(mesh: Mesh, count: int = SHAPE_DNA_COUNT) -> np.ndarray:
    """(count,) Shape-DNA computed directly on `mesh` (its own resolution, any scale)."""
    stiffness, mass = cotangent_laplacian(mesh.vertices, mesh.faces)
    # a few spare pairs: each connected component adds a zero eigenvalue before λ_1
    spectrum = smallest_eigenpairs(stiffness, mass, count + 8)
    return shape_dna(spectrum.eigenvalues, area=mesh.area(), count=count)


def euclidean_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, c), (q, c) -> (n, q) L2 distances (Shape-DNA)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    # direct differences, not |a|²-2ab+|b|²: exact zeros for equal rows, and c is small
    return np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=2))


def sample_surface(mesh: Mesh, count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, 3) points uniform over the surface: a face with probability ∝ area, then a uniform
    point of that triangle (the square-root barycentric rule of Osada et al. §4.2)."""
    areas = mesh.face_areas()
    total = areas.sum()
    if not (np.isfinite(total) and total > 0):  # else NumPy's "probabilities contain NaN"
        raise ValueError("cannot sample a surface of zero area")
    faces = rng.choice(mesh.n_faces, size=count, p=areas / total)
    r1 = np.sqrt(rng.random(count))[:, None]
    r2 = rng.random(count)[:, None]
    a, b, c = (mesh.vertices[mesh.faces[faces, i]] for i in range(3))
    return (1.0 - r1) * a + r1 * (1.0 - r2) * b + r1 * r2 * c


def d2_histogram(
    mesh: Mesh, pairs: int = D2_PAIRS, bins: int = D2_BINS, max_ratio: float = D2_MAX_RATIO, seed: int = 0
) -> np.ndarray:
    """(bins,) float64 D2 distribution summing to 1: distances of `pairs` random point pairs,
    divided by their mean, binned over [0, max_ratio]."""
    rng = np.random.default_rng(seed)
    p = sample_surface(mesh, pairs, rng)
    q = sample_surface(mesh, pairs, rng)
    dist = np.linalg.norm(p - q, axis=1)  # (pairs,)
    mean = dist.mean()
    if not mean > 0:
        raise ValueError("D2 needs a surface of non-zero extent")
    ratio = np.minimum(dist / mean, np.nextafter(max_ratio, 0.0))
    hist, _ = np.histogram(ratio, bins=bins, range=(0.0, max_ratio))
    return hist / hist.sum()
