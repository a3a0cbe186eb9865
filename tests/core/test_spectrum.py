"""Eigenpairs of L φ = λ M φ against the sphere's known spectrum, and the solver's contracts."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import trimesh

from app.core import spectrum
from app.core.laplacian import cotangent_laplacian
from app.core.spectrum import (
    SpectrumError,
    _m_orthonormalize,
    _mixed_precision,
    first_nonzero,
    smallest_eigenpairs,
)


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


# The per-component solve when the components' vertices are interleaved, and the M-normalisation of
# ARPACK's vectors. Two equal spheres share every eigenvalue, so a solve over
# both at once may return any mixture of the pair; the per-component solve must give vectors that each
# live on one sphere, whatever the vertex order.


def _interleaved_spheres(parts: int):
    """`parts` equal icospheres (42 vertices each) with their vertices shuffled together."""
    s = trimesh.creation.icosphere(subdivisions=1)
    v = np.vstack([np.asarray(s.vertices) + [4.0 * i, 0, 0] for i in range(parts)])
    f = np.vstack([np.asarray(s.faces) + i * len(s.vertices) for i in range(parts)])
    perm = np.random.default_rng(0).permutation(len(v))  # new index of each old vertex
    where = np.empty_like(perm)
    where[perm] = np.arange(len(v))
    labels = np.repeat(np.arange(parts), len(s.vertices))
    return v[where], perm[f], labels[where]


def _support(phi: np.ndarray, labels: np.ndarray) -> list[int]:
    """How many components each eigenvector touches."""
    return [len(np.unique(labels[np.abs(c) > 1e-9 * np.abs(c).max()])) for c in phi.T]


def test_every_vector_of_the_per_component_solve_lives_on_one_component():
    for parts in (2, 3):
        v, f, labels = _interleaved_spheres(parts)
        L, M = cotangent_laplacian(v, f)
        spec = smallest_eigenpairs(L, M, k=20, method="blocks")
        assert _support(spec.eigenvectors, labels) == [1] * 20
        assert np.all(spec.eigenvalues[:parts] < 1e-10) and spec.eigenvalues[parts] > 1e-3
        exact = smallest_eigenpairs(L, M, k=20, method="exact")
        assert np.allclose(spec.eigenvalues, exact.eigenvalues, rtol=1e-8, atol=1e-10)


def test_m_orthonormalize_gives_unit_m_norm_columns():
    rng = np.random.default_rng(1)
    mass = rng.random(30) + 0.5
    vecs = rng.normal(size=(30, 4)) * [0.5, 2.0, 3.0, 10.0]
    out = _m_orthonormalize(vecs, mass)
    assert np.allclose(np.einsum("ik,i,ik->k", out, mass, out), 1.0)
    assert np.allclose(out / vecs, (out / vecs)[0])  # each column only rescaled, by a positive factor
    assert np.all(out / vecs > 0)


def test_the_mixed_precision_solve_is_accepted_and_exact_to_double_precision(shrec_mesh):
    """On a unit-area mesh the float32 subspace plus the float64 Rayleigh-Ritz step is accurate: it is
    kept (not replaced by the exact solve), its eigenvalues are LAPACK's float64 ones, its vectors
    orthonormal eigenvectors of A = M^-1/2 L M^-1/2."""
    v = shrec_mesh.vertices / np.sqrt(shrec_mesh.area())
    L, M = cotangent_laplacian(v, shrec_mesh.faces)
    inv = 1.0 / np.sqrt(M.diagonal())
    a = sp.csr_matrix(sp.diags(inv) @ L @ sp.diags(inv))
    a = sp.csr_matrix(0.5 * (a + a.T))
    vals, psi = _mixed_precision(a, 40)
    assert psi is not None
    exact = la.eigh(a.toarray(), eigvals_only=True, subset_by_index=[0, 39])
    # λ_0 = 0 is exact only relative to the spectrum's scale (double precision of ‖A‖ over a float32
    # subspace): 1.2e-9 against λ_39 = 350 with numpy 2.4 / scipy 1.17, under 1e-9 before
    assert np.allclose(vals, exact, rtol=1e-9, atol=1e-11 * exact.max())
    assert np.allclose(psi.T @ psi, np.eye(40), atol=1e-10)
    assert np.abs(a @ psi - psi * vals).max() < 1e-2


@pytest.mark.parametrize(
    ("eigenvalues", "index"),
    [
        ([0.0, 0.0, 3.0], 2),  # one zero per component; a single non-zero one is enough
        ([0.0, 1e-7, 5.0, 1e3], 2),  # numerical zero: relative to the largest eigenvalue, not the next
        ([0.0, 1.5e-8, 0.5], 1),  # below 1 the tolerance stays 1e-8 absolute
        ([0.0, 1e-8, 0.5], 2),  # exactly at the tolerance is still zero
    ],
)
def test_first_nonzero(eigenvalues, index):
    assert first_nonzero(np.array(eigenvalues)) == index


def test_first_nonzero_of_an_all_zero_spectrum_is_an_error_in_words():
    with pytest.raises(SpectrumError, match="^the spectrum has no non-zero eigenvalue$"):
        first_nonzero(np.zeros(4))


class FlakyArpack:
    """sla.eigsh that fails its first `failures` calls, recording how each call was made."""

    def __init__(self, failures: int) -> None:
        self.failures = failures
        self.calls: list[dict] = []

    def __call__(self, A, k, M, sigma, which, v0, ncv, tol):
        self.calls.append({"sigma": sigma, "ncv": ncv, "v0": v0.copy(), "k": k})
        if len(self.calls) <= self.failures:
            raise sla.ArpackNoConvergence("no convergence", np.zeros(0), np.zeros((A.shape[0], 0)))
        return REAL_EIGSH(A, k=k, M=M, sigma=sigma, which=which, v0=v0, ncv=ncv, tol=tol)


REAL_EIGSH = sla.eigsh


@pytest.fixture(scope="module")
def ellipsoid_operators(ellipsoid_mesh):
    L, M = cotangent_laplacian(ellipsoid_mesh.vertices, ellipsoid_mesh.faces)
    exact = smallest_eigenpairs(L, M, k=10, method="exact")
    return L, M, exact


def test_a_convergence_failure_is_retried_with_another_start_and_a_larger_subspace(
    ellipsoid_operators, monkeypatch
):
    L, M, exact = ellipsoid_operators
    flaky = FlakyArpack(failures=1)
    monkeypatch.setattr(spectrum.sla, "eigsh", flaky)
    spec = smallest_eigenpairs(L, M, k=10, method="sparse", seed=3)
    assert np.allclose(spec.eigenvalues, exact.eigenvalues, rtol=1e-6, atol=1e-9)
    first, second = flaky.calls
    assert first["ncv"] is None and second["ncv"] == 21  # ARPACK's default, then its advice: 2k + 1
    assert not np.array_equal(first["v0"], second["v0"])
    lam1 = exact.eigenvalues[1]
    assert 0 < -first["sigma"] < -second["sigma"] < 1e-3 * lam1  # below the spectrum, close to 0
    again = FlakyArpack(failures=1)
    monkeypatch.setattr(spectrum.sla, "eigsh", again)
    smallest_eigenpairs(L, M, k=10, method="sparse", seed=3)
    assert np.array_equal(again.calls[0]["v0"], first["v0"])  # the start vectors come from the seed


def test_the_shifts_follow_the_operator_scale_and_the_retry_subspace_has_a_floor(ellipsoid_mesh, monkeypatch):
    """Scaling the mesh by s scales L M^-1 by 1/s²: both shifts follow, so they stay as close to 0
    relative to the spectrum; a small k still gets a subspace of 20 on the retry."""
    sigmas = []
    for s in (1.0, 10.0):
        L, M = cotangent_laplacian(ellipsoid_mesh.vertices * s, ellipsoid_mesh.faces)
        flaky = FlakyArpack(failures=1)
        monkeypatch.setattr(spectrum.sla, "eigsh", flaky)
        smallest_eigenpairs(L, M, k=3, method="sparse")
        sigmas.append([c["sigma"] for c in flaky.calls])
        assert flaky.calls[1]["ncv"] == 20
    assert np.allclose(np.array(sigmas[1]) * 100.0, sigmas[0], rtol=1e-9)


def test_the_retry_subspace_is_capped_by_the_mesh_size(monkeypatch):
    s = trimesh.creation.icosphere(subdivisions=0)  # 12 vertices: 2k + 1 = 21 > n - 1 = 11
    L, M = cotangent_laplacian(np.asarray(s.vertices), np.asarray(s.faces))
    flaky = FlakyArpack(failures=1)
    monkeypatch.setattr(spectrum.sla, "eigsh", flaky)
    smallest_eigenpairs(L, M, k=5, method="sparse")
    assert flaky.calls[1]["ncv"] == 11


def test_after_two_failures_a_small_mesh_falls_back_to_the_dense_solve(ellipsoid_operators, monkeypatch):
    L, M, exact = ellipsoid_operators
    monkeypatch.setattr(spectrum.sla, "eigsh", FlakyArpack(failures=2))
    spec = smallest_eigenpairs(L, M, k=10, method="sparse")
    assert np.allclose(spec.eigenvalues, exact.eigenvalues, rtol=1e-8, atol=1e-9)
    gram = spec.eigenvectors.T @ (M @ spec.eigenvectors)
    assert np.allclose(gram, np.eye(10), atol=1e-8)


def test_after_two_failures_a_large_mesh_is_an_error_naming_the_cause(ellipsoid_operators, monkeypatch):
    L, M, _ = ellipsoid_operators
    monkeypatch.setattr(spectrum, "DENSE_MAX", (L.shape[0] - 1) // 2)  # this mesh is "large" now
    monkeypatch.setattr(spectrum.sla, "eigsh", FlakyArpack(failures=2))
    with pytest.raises(SpectrumError, match="^the eigen-solver did not converge: .*no convergence"):
        smallest_eigenpairs(L, M, k=10, method="sparse")
    monkeypatch.setattr(spectrum, "DENSE_MAX", L.shape[0] // 2)  # exactly 2 * DENSE_MAX: still dense
    monkeypatch.setattr(spectrum.sla, "eigsh", FlakyArpack(failures=2))
    assert smallest_eigenpairs(L, M, k=10, method="sparse").eigenvalues.shape == (10,)


def test_k_is_at_least_one_and_a_massless_vertex_is_refused_in_words(ellipsoid_operators):
    L, M, exact = ellipsoid_operators
    one = smallest_eigenpairs(L, M, k=1)
    assert one.eigenvalues.shape == (1,) and one.eigenvectors.shape == (L.shape[0], 1)
    mass = M.diagonal().copy()
    mass[7] = 0.0
    with pytest.raises(SpectrumError, match="^a vertex has zero area: the mass matrix is singular$"):
        smallest_eigenpairs(L, sp.diags(mass), k=5)
    with pytest.raises(ValueError, match="^unknown eigen-solver method 'lobpcg'$"):
        smallest_eigenpairs(L, M, k=5, method="lobpcg")


def test_auto_solves_a_multi_part_mesh_up_to_dense_max_per_component(monkeypatch):
    v, f, labels = _interleaved_spheres(2)
    L, M = cotangent_laplacian(v, f)
    monkeypatch.setattr(spectrum, "DENSE_MAX", L.shape[0])  # exactly at the limit: still dense, per part
    spec = smallest_eigenpairs(L, M, k=20)
    assert _support(spec.eigenvectors, labels) == [1] * 20


def test_auto_uses_arpack_above_dense_max_only(ellipsoid_operators, monkeypatch):
    L, M, exact = ellipsoid_operators
    n = L.shape[0]
    for dense_max, arpack in ((n, False), (n - 1, True)):
        spy = FlakyArpack(failures=0)
        monkeypatch.setattr(spectrum, "DENSE_MAX", dense_max)
        monkeypatch.setattr(spectrum.sla, "eigsh", spy)
        spec = smallest_eigenpairs(L, M, k=10)
        assert bool(spy.calls) is arpack
        assert np.allclose(spec.eigenvalues, exact.eigenvalues, rtol=1e-6, atol=1e-9)


def test_the_sparse_solve_is_reproducible_and_seeded(ellipsoid_operators, monkeypatch):
    L, M, _ = ellipsoid_operators
    runs = []
    for seed in (None, 0, 0):
        spy = FlakyArpack(failures=0)
        monkeypatch.setattr(spectrum.sla, "eigsh", spy)
        smallest_eigenpairs(L, M, k=10, method="sparse", **({} if seed is None else {"seed": seed}))
        runs.append(spy.calls[0]["v0"])
    assert np.array_equal(runs[0], runs[1]) and np.array_equal(runs[1], runs[2])  # the default seed is 0
    assert np.array_equal(runs[0], np.random.default_rng(0).standard_normal(L.shape[0]))


def test_round_off_below_zero_is_clipped(ellipsoid_operators, monkeypatch):
    """L is positive semi-definite: a solver's -1e-15 for the constant mode is reported as 0."""
    L, M, exact = ellipsoid_operators
    dense = spectrum._dense

    def with_negative_zero(stiffness, mass_diag, k, mixed=True):
        vals, vecs = dense(stiffness, mass_diag, k, mixed)
        vals = vals.copy()
        vals[0] = -1e-15
        return vals, vecs

    monkeypatch.setattr(spectrum, "_dense", with_negative_zero)
    spec = smallest_eigenpairs(L, M, k=5, method="dense")
    assert spec.eigenvalues[0] == 0.0 and np.all(spec.eigenvalues >= 0)
