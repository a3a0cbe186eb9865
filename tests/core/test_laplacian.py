"""Both Laplacians (cotangent, intrinsic Delaunay) and the lumped mass, against continuous identities."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.laplacian import LAPLACIANS, cotangent_laplacian, intrinsic_delaunay_laplacian, laplacian


@pytest.mark.parametrize("kind", LAPLACIANS)
def test_rows_sum_to_zero_and_matrix_is_symmetric_psd(shrec_mesh, kind):
    L, M = laplacian(shrec_mesh.vertices, shrec_mesh.faces, kind)
    assert np.allclose(np.asarray(L.sum(axis=1)).ravel(), 0.0, atol=1e-10)
    assert abs(L - L.T).max() < 1e-12
    eig = np.linalg.eigvalsh(L.toarray())
    assert eig.min() > -1e-9 * eig.max()


@pytest.mark.parametrize("kind", LAPLACIANS)
def test_mass_is_total_area(shrec_mesh, kind):
    _, M = laplacian(shrec_mesh.vertices, shrec_mesh.faces, kind)
    assert np.isclose(M.diagonal().sum(), shrec_mesh.area(), rtol=1e-12)


def test_dirichlet_energy_of_linear_function_is_area_on_a_plane():
    # On a flat patch, f(x, y) = x has |grad f| = 1, so f^T L f = ∫|∇f|² = area (interior and boundary alike).
    xs, ys = np.meshgrid(np.linspace(0, 2, 9), np.linspace(0, 1, 6))
    vertices = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    faces = []
    for r in range(5):
        for c in range(8):
            a, b, d, e = r * 9 + c, r * 9 + c + 1, (r + 1) * 9 + c, (r + 1) * 9 + c + 1
            faces += [[a, b, e], [a, e, d]]
    L, _ = cotangent_laplacian(vertices, np.array(faces))
    f = vertices[:, 0]
    assert np.isclose(f @ L @ f, 2.0, rtol=1e-12)


def test_single_triangle_weights_are_half_cotangents():
    # right isosceles triangle: angles 90°, 45°, 45° -> cot = 0, 1, 1
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    L, M = cotangent_laplacian(v, np.array([[0, 1, 2]]))
    dense = L.toarray()
    # edge (1,2) is opposite the right angle at 0: weight cot(90°)/2 = 0
    assert np.isclose(dense[1, 2], 0.0)
    # edges (0,1) and (0,2) are opposite 45° angles: weight -cot(45°)/2 = -0.5
    assert np.isclose(dense[0, 1], -0.5) and np.isclose(dense[0, 2], -0.5)
    assert np.allclose(M.diagonal(), 0.5 / 3)


# The Laplacian's shape contract and its by-name choice: L and M are (n, n)
# for n vertices even when the last one is in no face (its row and mass are zero), and laplacian()
# picks the cotangent operator by default, the intrinsic one by name, and refuses others in words.


def _sphere() -> tuple[np.ndarray, np.ndarray]:
    s = trimesh.creation.icosphere(subdivisions=1)
    return np.asarray(s.vertices), np.asarray(s.faces, np.int64)


def test_a_vertex_in_no_face_still_has_its_row_and_zero_mass():
    v, f = _sphere()
    n = len(v)
    extra = np.vstack([v, [[5.0, 5.0, 5.0]]])  # the last vertex: referenced by no face
    L, M = cotangent_laplacian(extra, f)
    assert L.shape == M.shape == (n + 1, n + 1)
    assert abs(L[n]).sum() == 0 and M.diagonal()[n] == 0
    L0, M0 = cotangent_laplacian(v, f)
    assert abs(L[:n, :n] - L0).max() == 0 and np.array_equal(M.diagonal()[:n], M0.diagonal())
    Li, Mi = intrinsic_delaunay_laplacian(extra, f)
    assert Li.shape == Mi.shape == (n + 1, n + 1) and Mi.diagonal()[n] == 0


def test_laplacian_by_name():
    v, f = _sphere()
    for (L, M), (L2, M2) in [
        (laplacian(v, f), cotangent_laplacian(v, f)),  # the default: the paper's operator
        (laplacian(v, f, "cotangent"), cotangent_laplacian(v, f)),
        (laplacian(v, f, "intrinsic"), intrinsic_delaunay_laplacian(v, f)),
    ]:
        assert abs(L - L2).max() == 0 and np.array_equal(M.diagonal(), M2.diagonal())
    with pytest.raises(ValueError, match=r"^laplacian must be one of cotangent, intrinsic, not 'graph'$"):
        laplacian(v, f, "graph")
