"""Cotangent Taubin on a hand-solvable mesh (issue 15 mutation pass): one equilateral triangle and a
vertex in no face. The triangle's weights are equal, so W averages the other two vertices and each
step s scales the offsets from the centroid by 1 - 1.5 s; the lone vertex has no neighbour and stays."""

from __future__ import annotations

import numpy as np

from app.core.mesh import Mesh
from app.core.smoothing import cotangent_taubin, cotangent_weights

TRIANGLE = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, np.sqrt(3.0), 0.0]])
LONE = np.array([[5.0, 4.0, 3.0]])


def _mesh() -> Mesh:
    return Mesh(np.vstack([TRIANGLE, LONE]), np.array([[0, 1, 2]], np.int64))


def test_weights_of_a_lone_triangle_and_a_vertex_in_no_face():
    w, has = cotangent_weights(_mesh())  # every cotangent weight is cot 60° / 2 < 1 per row
    assert has.tolist() == [True, True, True, False]
    expected = np.zeros((4, 4))
    expected[:3, :3] = 0.5
    np.fill_diagonal(expected, 0.0)
    assert np.allclose(w.toarray(), expected, atol=1e-15)


def test_one_iteration_shrinks_the_triangle_about_its_centroid_and_leaves_the_lone_vertex():
    mesh = _mesh()
    out = cotangent_taubin(mesh, 1, lamb=0.5, mu=-0.53)
    centroid = TRIANGLE.mean(axis=0)
    factor = (1 - 1.5 * 0.5) * (1 - 1.5 * -0.53)
    assert np.allclose(out.vertices[:3], centroid + factor * (TRIANGLE - centroid), atol=1e-12)
    assert np.array_equal(out.vertices[3:], LONE)
    assert np.array_equal(out.faces, mesh.faces)
    two = cotangent_taubin(mesh, 2).vertices  # W from the input geometry: the same factor again
    assert np.allclose(two[:3], centroid + factor**2 * (TRIANGLE - centroid), atol=1e-12)
