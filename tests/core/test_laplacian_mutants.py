"""The Laplacian's shape contract and its by-name choice (issue 15 mutation pass): L and M are (n, n)
for n vertices even when the last one is in no face (its row and mass are zero), and laplacian()
picks the cotangent operator by default, the intrinsic one by name, and refuses others in words."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.laplacian import cotangent_laplacian, intrinsic_delaunay_laplacian, laplacian


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
