"""Smallest-k eigenpairs of the generalised problem L φ = λ M φ.

Two strategies, chosen by size:
- dense (n <= DENSE_MAX): M is diagonal, so A = M^-1/2 L M^-1/2 is symmetric and LAPACK's
  `eigh(subset_by_index=...)` returns the k smallest pairs directly; at the canonical resolution
  (~10^3 vertices) faster than Lanczos. Mixed precision: the O(n^3) tridiagonalisation runs in
  float32 (~2x faster), then one float64 Rayleigh-Ritz step on the k-dimensional subspace restores
  double-precision eigenvalues (error ~ residual^2) and vectors; if the residuals are not small the
  exact float64 solve runs instead. (method="exact" forces that solve.)
- blocks (several connected components, n <= DENSE_MAX): the dense solve per component; the
  union of the blocks' pairs is the spectrum (L and M are block diagonal).
- sparse: ARPACK shift-invert around a small negative shift (L is singular, so σ = 0 cannot be
  factored); on a convergence failure retry with another start vector and a larger subspace, then
  fall back to dense if the mesh is small enough.
Eigenvectors are returned M-orthonormal: Φᵀ M Φ = I.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as sla

DENSE_MAX = 3000
# accept the mixed-precision result when every residual ‖Aψ - μψ‖ is below this fraction of λ_k
MIXED_RESIDUAL_TOL = 1e-3
# the dense solve is refused when λ_k <= RELIABLE_ABOVE * eps * ||A|| (at the canonical resolution
# λ_k / ||A|| is ~0.1-0.5)
RELIABLE_ABOVE = 1e3


class SpectrumError(RuntimeError):
    """The eigen-solver did not converge on this mesh."""


@dataclass(frozen=True)
class Spectrum:
    """eigenvalues : (k,) float64 ascending;  eigenvectors : (n, k) float64, M-orthonormal."""

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray


def smallest_eigenpairs(
    stiffness: sp.spmatrix, mass: sp.spmatrix, k: int, method: str = "auto", seed: int = 0
) -> Spectrum:
    """k smallest eigenpairs (k is capped at n - 1)."""
    n = stiffness.shape[0]
    k = max(1, min(k, n - 1))
    mass_diag = np.asarray(mass.diagonal(), dtype=np.float64)
    if np.any(mass_diag <= 0):
        raise SpectrumError("a vertex has zero area: the mass matrix is singular")
    if not (np.all(np.isfinite(mass_diag)) and np.all(np.isfinite(sp.csr_matrix(stiffness).data))):
        raise SpectrumError("the Laplacian has non-finite entries (a degenerate triangle?)")
    # components only matter to the dense path: large meshes go to ARPACK without the graph search
    small = method == "blocks" or (method == "auto" and n <= DENSE_MAX)
    blocks = _component_blocks(stiffness) if small else []
    if method == "auto":
        method = "sparse" if n > DENSE_MAX else "blocks" if len(blocks) > 1 else "dense"
    if method == "blocks":
        vals, vecs = _block_diagonal(stiffness, mass_diag, k, blocks)
    elif method == "dense":
        vals, vecs = _dense(stiffness, mass_diag, k)
    elif method == "exact":
        vals, vecs = _dense(stiffness, mass_diag, k, mixed=False)
    elif method == "sparse":
        vals, vecs = _sparse_with_retry(stiffness, mass, mass_diag, k, seed)
    else:
        raise ValueError(f"unknown eigen-solver method {method!r}")
    order = np.argsort(vals)
    vals = np.clip(vals[order], 0.0, None)  # L is PSD: tiny negatives are round-off
    return Spectrum(vals, vecs[:, order])


def _component_blocks(stiffness: sp.spmatrix) -> list[np.ndarray]:
    """Vertex indices of each connected component of the stiffness matrix's graph."""
    count, labels = sp.csgraph.connected_components(sp.csr_matrix(stiffness), directed=False)
    if count == 1:
        return [np.arange(stiffness.shape[0])]
    order = np.argsort(labels, kind="stable")
    return np.split(order, np.cumsum(np.bincount(labels, minlength=count))[:-1])


def _block_diagonal(
    stiffness: sp.spmatrix, mass_diag: np.ndarray, k: int, blocks: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Solve each component on its own and keep the k smallest pairs of the union.

    L and M are block diagonal once vertices are grouped by component, so the union of the blocks'
    eigenpairs (each zero outside its block) *is* the spectrum. Many equal parts (a plate of printed
    pieces, an instanced asset) make eigenvalues of multiplicity c, which LAPACK's MRRR (evr) handles
    slowly; the blocks are also much smaller: sum(n_i^3) instead of n^3.
    """
    n = stiffness.shape[0]
    csr = sp.csr_matrix(stiffness)
    vals_parts, vecs_parts = [], []
    for idx in blocks:
        sub = csr[idx][:, idx]
        # small blocks: the exact float64 solve is cheap and has no subspace to verify
        vals_b, vecs_b = _dense(sub, mass_diag[idx], min(k, len(idx)), mixed=len(idx) > 200)
        full = np.zeros((n, len(vals_b)))
        full[idx] = vecs_b
        vals_parts.append(vals_b)
        vecs_parts.append(full)
    vals = np.concatenate(vals_parts)
    keep = np.argsort(vals, kind="stable")[:k]
    return vals[keep], np.concatenate(vecs_parts, axis=1)[:, keep]


def _dense(
    stiffness: sp.spmatrix, mass_diag: np.ndarray, k: int, mixed: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    inv_sqrt = 1.0 / np.sqrt(mass_diag)
    scaling = sp.diags(inv_sqrt)
    a = (scaling @ sp.csr_matrix(stiffness) @ scaling).tocsr()
    a = (0.5 * (a + a.T)).tocsr()  # (n, n) sparse, symmetric
    psi = None
    if mixed:
        vals, psi = _mixed_precision(a, k)
    if psi is None:
        vals, psi = la.eigh(
            a.toarray(), subset_by_index=[0, k - 1], driver="evr", overwrite_a=True, check_finite=False
        )
    # a dense solver's eigenvalues carry an absolute error of ~eps ||A||: when even the largest of the
    # k is inside it (a weight of 1e16 beside weights of 1), the spectrum is round-off, not the mesh's
    norm = float(abs(a).sum(axis=1).max()) if a.nnz else 0.0
    if len(vals) >= 2 and not vals[-1] > RELIABLE_ABOVE * np.finfo(np.float64).eps * norm:
        raise SpectrumError("the Laplacian is too ill-conditioned for its spectrum to be computed "
                            f"(largest of {len(vals)} eigenvalues {vals[-1]:.3g}, operator norm {norm:.3g})")
    return vals, psi * inv_sqrt[:, None]  # φ = M^-1/2 ψ is M-orthonormal


def _mixed_precision(a: sp.csr_matrix, k: int) -> tuple[np.ndarray, np.ndarray | None]:
    """float32 eigh for the subspace, float64 Rayleigh-Ritz on it; (vals, None) if not accurate."""
    with np.errstate(over="ignore"):  # an overflowing float32 copy is detected below
        a32 = a.astype(np.float32).toarray()
    _, w32 = la.eigh(a32, subset_by_index=[0, k - 1], driver="evr", overwrite_a=True, check_finite=False)
    if w32.shape[1] < k or not np.all(np.isfinite(w32)):  # float32 overflowed (entries ~1e19 and up)
        return np.zeros(0), None
    q, _ = la.qr(w32.astype(np.float64), mode="economic", overwrite_a=True, check_finite=False)  # (n, k)
    aq = a @ q  # (n, k)
    small = q.T @ aq  # (k, k) = Qᵀ A Q
    vals, y = la.eigh(0.5 * (small + small.T), check_finite=False)
    psi = q @ y  # (n, k) orthonormal Ritz vectors
    residual = np.linalg.norm(aq @ y - psi * vals, axis=0)  # (k,)
    if not np.all(residual <= MIXED_RESIDUAL_TOL * max(abs(float(vals[-1])), 1.0)):
        return vals, None
    return vals, psi


def _sparse_with_retry(
    stiffness: sp.spmatrix, mass: sp.spmatrix, mass_diag: np.ndarray, k: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    n = stiffness.shape[0]
    # shift relative to the operator's scale so that L - σM is definite and well conditioned
    scale = float(np.median(stiffness.diagonal() / mass_diag))
    attempts = [(-1e-8 * scale, None), (-1e-6 * scale, min(n - 1, max(2 * k + 1, 20)))]
    rng = np.random.default_rng(seed)
    last: Exception | None = None
    for sigma, ncv in attempts:
        try:
            vals, vecs = sla.eigsh(
                stiffness.tocsc(), k=k, M=mass.tocsc(), sigma=sigma, which="LM",
                v0=rng.standard_normal(n), ncv=ncv, tol=0.0,
            )
            return vals, _m_orthonormalize(vecs, mass_diag)
        except (sla.ArpackNoConvergence, sla.ArpackError, RuntimeError) as exc:
            last = exc
    if n <= 2 * DENSE_MAX:
        return _dense(stiffness, mass_diag, k)
    raise SpectrumError(f"the eigen-solver did not converge: {last}")


def _m_orthonormalize(vecs: np.ndarray, mass_diag: np.ndarray) -> np.ndarray:
    """Re-normalise each column to unit M-norm (ARPACK returns M-orthogonal vectors up to round-off)."""
    norms = np.sqrt(np.einsum("ik,i,ik->k", vecs, mass_diag, vecs))
    return vecs / norms


def first_nonzero(eigenvalues: np.ndarray, rel_tol: float = 1e-8) -> int:
    """Index of the first eigenvalue above numerical zero.

    A mesh with c connected components has c zero eigenvalues; the paper's λ2 (which sets
    t_max = 4 ln10 / λ2) is the first *non-zero* one, so t_max stays finite for any c.
    """
    tol = rel_tol * max(float(eigenvalues[-1]), 1.0)
    nz = np.flatnonzero(eigenvalues > tol)
    if nz.size == 0:
        raise SpectrumError("the spectrum has no non-zero eigenvalue")
    return int(nz[0])
