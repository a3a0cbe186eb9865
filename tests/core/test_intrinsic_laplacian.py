"""The intrinsic Delaunay Laplacian (laplacian="intrinsic"): the cotangent operator of the same surface
with its edges flipped intrinsically until Delaunay. Checked against identities and the sphere's spectrum."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.spatial
import trimesh

from app.core.laplacian import cotangent_laplacian, intrinsic_delaunay_laplacian, laplacian


def _plane(nx: int = 9, ny: int = 6) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = np.meshgrid(np.linspace(0, 2, nx), np.linspace(0, 1, ny))
    vertices = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    faces = []
    for r in range(ny - 1):
        for c in range(nx - 1):
            a, b, d, e = r * nx + c, r * nx + c + 1, (r + 1) * nx + c, (r + 1) * nx + c + 1
            faces += [[a, b, e], [a, e, d]]
    return vertices, np.array(faces)


def test_equals_cotangent_on_a_delaunay_mesh():
    # an icosphere's edges are all Delaunay: no flip, the same operator up to the mollification,
    # and the same lumped mass
    sphere = trimesh.creation.icosphere(subdivisions=2)
    Li, Mi = intrinsic_delaunay_laplacian(sphere.vertices, sphere.faces)
    Lc, Mc = cotangent_laplacian(sphere.vertices, sphere.faces)
    assert abs(Li - Lc).max() < 1e-4 * abs(Lc).max()
    assert np.allclose(Mi.diagonal(), Mc.diagonal(), rtol=1e-12)


def test_flips_a_non_delaunay_edge_and_keeps_weights_nonnegative():
    # two triangles sharing edge 0-1 with both opposite angles near 180°: cot α + cot β < 0 there
    v = np.array([[-1.0, 0, 0], [1, 0, 0], [0, 0.1, 0], [0, -0.1, 0]])
    f = np.array([[0, 1, 2], [1, 0, 3]])
    Lc, _ = cotangent_laplacian(v, f)
    assert Lc[0, 1] > 0  # the extrinsic operator has a positive off-diagonal (not an M-matrix)
    Li, Mi = intrinsic_delaunay_laplacian(v, f)
    off = Li.toarray() - np.diag(Li.diagonal())
    assert off.max() <= 1e-12  # Delaunay: every cotangent weight ≥ 0
    assert abs(Li[0, 1]) < 1e-9  # 0 and 1 are no longer joined by an edge: the flip made 2-3
    assert Li[2, 3] < 0
    assert np.isclose(Mi.diagonal().sum(), 0.2, rtol=1e-4)  # the same surface: area unchanged


def test_dirichlet_energy_of_linear_function_is_area_on_a_plane():
    # linear precision: on a flat patch ∫|∇x|² = area, whatever the intrinsic triangulation
    v, f = _plane()
    L, _ = intrinsic_delaunay_laplacian(v, f)
    x = v[:, 0]
    assert np.isclose(x @ L @ x, 2.0, rtol=1e-4)


def test_sphere_spectrum_is_l_times_l_plus_one():
    # unit sphere: eigenvalues l(l+1) with multiplicity 2l+1
    sphere = trimesh.creation.icosphere(subdivisions=3)
    L, M = intrinsic_delaunay_laplacian(sphere.vertices, sphere.faces)
    lam = scipy.linalg.eigh(L.toarray(), M.toarray(), eigvals_only=True, subset_by_index=[0, 15])
    expected = np.array([0] + [2] * 3 + [6] * 5 + [12] * 7, dtype=float)
    assert np.allclose(lam, expected, rtol=0.02, atol=1e-8)


def test_the_spectrum_depends_far_less_on_the_triangulation_than_cotangent():
    # 64 points of a flat square, triangulated twice: Delaunay, and Delaunay of the points squashed
    # along y (valid, but full of long thin triangles). The intrinsic operator flips both towards the
    # same intrinsic Delaunay triangulation (the lumped mass is still each mesh's own, as in the
    # paper); the extrinsic cotangent spectrum moves with the slivers.
    rng = np.random.default_rng(0)
    corners = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    pts = np.vstack([corners, rng.uniform(-0.5, 0.5, (60, 2))])
    v = np.column_stack([pts, np.zeros(len(pts))])
    spectra = {}
    for name, scale in (("delaunay", 1.0), ("sliver", 0.02)):
        faces = _counterclockwise(pts, scipy.spatial.Delaunay(pts * np.array([1.0, scale])).simplices)
        for kind in ("cotangent", "intrinsic"):
            L, M = laplacian(v, faces, kind)
            spectra[name, kind] = scipy.linalg.eigh(L.toarray(), M.toarray(), eigvals_only=True)[1:11]
    cot = spectra["sliver", "cotangent"] / spectra["delaunay", "cotangent"]
    intr = spectra["sliver", "intrinsic"] / spectra["delaunay", "intrinsic"]
    assert np.abs(np.log(intr)).max() < 0.3  # within ~30 % (the two masses still differ)
    assert np.abs(np.log(cot)).max() > 0.9  # the extrinsic one is off by more than 2.5x
    assert np.abs(np.log(intr)).mean() < 0.25 * np.abs(np.log(cot)).mean()
    # and the low end approximates the square's Neumann spectrum: π², π² (64 random points: ~13 %)
    assert np.allclose(spectra["delaunay", "intrinsic"][:2], np.pi**2, rtol=0.15)


def _counterclockwise(pts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f, 3) faces reordered so each is counter-clockwise in the plane (consistent orientation)."""
    a, b, c = pts[faces[:, 0]], pts[faces[:, 1]], pts[faces[:, 2]]
    cross = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    out = faces.copy()
    out[cross < 0] = faces[cross < 0][:, [0, 2, 1]]
    return out


def test_unknown_kind_is_refused():
    v, f = _plane(3, 3)
    with pytest.raises(ValueError, match="laplacian must be one of"):
        laplacian(v, f, "graph")
