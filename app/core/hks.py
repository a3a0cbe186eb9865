"""Heat Kernel Signature (Sun, Ovsjanikov & Guibas 2009), the paper's eqs. 1–4."""

from __future__ import annotations

import numpy as np

from app.core.spectrum import Spectrum, first_nonzero

LN10_4 = 4.0 * np.log(10.0)


def time_scales(eigenvalues: np.ndarray, m: int = 100) -> np.ndarray:
    """(m,) times log-spaced over [4 ln10 / λ_k, 4 ln10 / λ_2] (eqs. 1–2).

    λ_2 is the first non-zero eigenvalue (see spectrum.first_nonzero), λ_k the largest computed.
    """
    lam2 = eigenvalues[first_nonzero(eigenvalues)]
    lamk = eigenvalues[-1]
    t_min, t_max = LN10_4 / lamk, LN10_4 / lam2
    return np.geomspace(t_min, t_max, m)


def heat_kernel_signature(spectrum: Spectrum, times: np.ndarray) -> np.ndarray:
    """(n, m) K_t(x, x) = Σ_i exp(-λ_i t) φ_i(x)² (eq. 3)."""
    decay = np.exp(-np.outer(spectrum.eigenvalues, times))  # (k, m)
    return (spectrum.eigenvectors**2) @ decay  # (n, k) @ (k, m) -> (n, m)


def normalize(hks: np.ndarray) -> np.ndarray:
    """(n, m) h(x) = c(x) K(x) with ‖h(x)‖₂ = 1 per vertex (eq. 4)."""
    norms = np.linalg.norm(hks, axis=1, keepdims=True)
    return hks / np.maximum(norms, np.finfo(float).tiny)
