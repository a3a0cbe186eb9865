"""The default BoF is eq. 7, an integral over the surface: it does not follow where the vertices are."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.mesh import Mesh
from app.core.pipeline import DescribeParams, describe
from app.core.vocabulary import EncodeParams, Vocabulary, l1_distance


def _split_half(mesh: Mesh) -> Mesh:
    """The same surface, its faces with x > 0 each split 1-to-3 at the centroid: conforming (no hanging
    vertex), flat splits (the surface does not move), three times the vertex density on one side."""
    v, f = mesh.vertices, mesh.faces
    right = v[f].mean(axis=1)[:, 0] > 0
    centroids = v[f[right]].mean(axis=1)  # (r, 3)
    c = np.arange(len(v), len(v) + len(centroids))
    a, b, d = f[right].T
    split = np.concatenate([np.column_stack(t) for t in ((a, b, c), (b, d, c), (d, a, c))])
    return Mesh(np.vstack([v, centroids]), np.vstack([f[~right], split]))


@pytest.mark.slow  # full describes of fine meshes
def test_a_denser_half_moves_the_integral_less_than_the_vertex_count():
    tm = trimesh.creation.icosphere(subdivisions=4)  # fine enough that both discretisations agree
    tm.vertices *= [1.8, 1.0, 0.6]
    tm.vertices[:, 0] += 0.3 * tm.vertices[:, 1] ** 2  # no symmetry between the two halves' shapes
    coarse = Mesh(np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64))
    dense = _split_half(coarse)
    assert dense.n_vertices > 2 * coarse.n_vertices
    assert np.isclose(dense.face_areas().sum(), coarse.face_areas().sum())
    # the surfaces as given; Weyl's t_min, so both use the same time scales
    params = DescribeParams(target_vertices=0, smoothing=0, k=30, time_range="weyl")
    a, b = describe(coarse, params), describe(dense, params)
    assert np.allclose(a.eigenvalues[1:10], b.eigenvalues[1:10], rtol=1e-2)  # the same surface
    vocab = Vocabulary.fit([a, b], size=8, run="run5", keypoints_only=False)

    def gap(area_weighted: bool) -> float:
        enc = EncodeParams(area_weighted=area_weighted)
        return float(l1_distance(vocab.encode(a, enc)[None], vocab.encode(b, enc)[None])[0, 0])

    # per vertex (eq. 8) the split half counts three times as much (measured L1 0.14); by area (eq. 7)
    # each half counts as the surface it is (0.007)
    assert gap(True) < 0.02 < 0.1 < gap(False)
    assert EncodeParams().area_weighted
