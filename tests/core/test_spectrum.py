"""Eigenpairs of L φ = λ M φ against the sphere's known spectrum, and the solver's contracts."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.laplacian import cotangent_laplacian
from app.core.spectrum import first_nonzero, smallest_eigenpairs


def sphere_spectrum(radius: float, lmax: int) -> np.ndarray:
    """Exact eigenvalues of the sphere: l(l+1)/r² with multiplicity 2l+1."""
    return np.concatenate([[deg * (deg + 1) / radius**2] * (2 * deg + 1) for deg in range(lmax + 1)])


@pytest.fixture(scope="module")
def icosphere():
    tm = trimesh.creation.icosphere(subdivisions=5, radius=2.0)
    return cotangent_laplacian(np.asarray(tm.vertices), np.asarray(tm.faces))


def test_icosphere_spectrum_matches_sphere_within_one_percent(icosphere):
    L, M = icosphere
    exact = sphere_spectrum(2.0, lmax=5)  # 36 eigenvalues, l <= 5
    spec = smallest_eigenpairs(L, M, k=len(exact), method="sparse")
    assert abs(spec.eigenvalues[0]) < 1e-8
    rel = np.abs(spec.eigenvalues[1:] - exact[1:]) / exact[1:]
    assert rel.max() < 0.01, rel
    # multiplicities: the gap between consecutive l-groups dwarfs the spread inside a group
    for deg in range(1, 6):
        group = spec.eigenvalues[deg * deg : (deg + 1) ** 2]
        assert np.ptp(group) < 0.02 * exact[deg * deg]


@pytest.mark.parametrize("method", ["dense", "sparse"])
def test_eigenvectors_are_mass_orthonormal(shrec_mesh, method):
    L, M = cotangent_laplacian(shrec_mesh.vertices, shrec_mesh.faces)
    spec = smallest_eigenpairs(L, M, k=40, method=method)
    gram = spec.eigenvectors.T @ (M @ spec.eigenvectors)
    assert np.allclose(gram, np.eye(40), atol=1e-6)
    residual = L @ spec.eigenvectors - (M @ spec.eigenvectors) * spec.eigenvalues
    assert np.abs(residual).max() < 1e-6 * spec.eigenvalues.max()


def test_dense_and_sparse_agree(shrec_mesh):
    L, M = cotangent_laplacian(shrec_mesh.vertices, shrec_mesh.faces)
    a = smallest_eigenpairs(L, M, k=30, method="dense").eigenvalues
    b = smallest_eigenpairs(L, M, k=30, method="sparse").eigenvalues
    assert np.allclose(a, b, rtol=1e-6, atol=1e-9)


def test_k_is_capped_below_n():
    tm = trimesh.creation.icosahedron()  # 12 vertices
    L, M = cotangent_laplacian(np.asarray(tm.vertices), np.asarray(tm.faces))
    spec = smallest_eigenpairs(L, M, k=300)
    assert spec.eigenvalues.shape == (11,) and spec.eigenvectors.shape == (12, 11)


def test_two_components_give_two_zero_eigenvalues():
    a = trimesh.creation.icosphere(subdivisions=2)
    b = a.copy()
    b.apply_translation([5.0, 0, 0])
    both = trimesh.util.concatenate([a, b])
    L, M = cotangent_laplacian(np.asarray(both.vertices), np.asarray(both.faces))
    spec = smallest_eigenpairs(L, M, k=10)
    assert np.all(spec.eigenvalues[:2] < 1e-8)
    assert first_nonzero(spec.eigenvalues) == 2


def test_many_parts_are_solved_per_component_with_the_same_spectrum():
    """Block-diagonal L, M: the per-component solve gives the global solve's eigenvalues, M-orthonormal
    vectors each living on one component, and the residual of the generalised problem vanishes."""
    parts = []
    for i, subdivisions in enumerate([1, 2, 1, 2, 1, 1]):  # unequal parts, some equal: multiplicities
        s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0 + 0.1 * (i % 2))
        s.apply_translation([4.0 * i, 0, 0])
        parts.append(s)
    mesh = trimesh.util.concatenate(parts)
    L, M = cotangent_laplacian(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    k = 60
    blocks = smallest_eigenpairs(L, M, k=k, method="blocks")
    exact = smallest_eigenpairs(L, M, k=k, method="exact")
    assert np.allclose(blocks.eigenvalues, exact.eigenvalues, rtol=1e-8, atol=1e-9)
    assert np.all(blocks.eigenvalues[:6] < 1e-8) and blocks.eigenvalues[6] > 1e-3  # one zero per part
    phi = blocks.eigenvectors
    assert np.allclose(phi.T @ (M @ phi), np.eye(k), atol=1e-8)
    residual = L @ phi - (M @ phi) * blocks.eigenvalues
    assert np.abs(residual).max() < 1e-8 * blocks.eigenvalues.max()
    labels = np.repeat(np.arange(len(parts)), [len(p.vertices) for p in parts])
    for column in phi.T:  # supported on exactly one component
        assert len(np.unique(labels[np.abs(column) > 1e-12])) == 1
    # "auto" picks the per-component solve for a multi-part mesh at the canonical size
    auto = smallest_eigenpairs(L, M, k=k)
    assert np.allclose(auto.eigenvalues, exact.eigenvalues, rtol=1e-8, atol=1e-9)


def _path_laplacian(weights: np.ndarray):
    """(n, n) graph Laplacian of a path whose edge i joins vertices i and i + 1 with weights[i]."""
    import scipy.sparse as sp

    n = len(weights) + 1
    i = np.arange(n - 1)
    w = sp.coo_matrix((weights, (i, i + 1)), shape=(n, n))
    w = (w + w.T).tocsr()
    return sp.diags(np.asarray(w.sum(axis=1)).ravel()) - w, sp.identity(n, format="csr")


def test_path_graph_spectrum_is_exact():
    # unit path of n vertices: λ_j = 2 - 2 cos(π j / n), j = 0..n-1 (free ends)
    n = 40
    L, M = _path_laplacian(np.ones(n - 1))
    spec = smallest_eigenpairs(L, M, k=10, method="dense")
    np.testing.assert_allclose(spec.eigenvalues, 2 - 2 * np.cos(np.pi * np.arange(10) / n), atol=1e-10)


def test_an_operator_beyond_float32_falls_back_to_the_exact_solve():
    # L x 1e30: its float32 copy overflows in the tridiagonal reduction (a 1e40 weight used to come
    # back with no eigenvalue at all: IndexError); the float64 solve runs instead
    n = 40
    L, M = _path_laplacian(np.full(n - 1, 1e30))
    spec = smallest_eigenpairs(L, M, k=10, method="dense")
    np.testing.assert_allclose(spec.eigenvalues[1:] / 1e30, (2 - 2 * np.cos(np.pi * np.arange(10) / n))[1:],
                               rtol=1e-9)


@pytest.mark.parametrize("weight", [1e16, 1e307, np.inf, np.nan])
def test_an_unresolvable_operator_is_a_spectrum_error_not_a_crash(weight):
    from app.core.spectrum import SpectrumError

    weights = np.ones(39)
    weights[5] = weight
    L, M = _path_laplacian(weights)
    with pytest.raises(SpectrumError):
        smallest_eigenpairs(L, M, k=10, method="dense")
