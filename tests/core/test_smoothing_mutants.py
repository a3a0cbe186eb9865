"""Taubin with the surface's weights on a hand-solvable mesh (issue 15 mutation pass): one
equilateral triangle and a vertex in no face. The triangle's weights are equal, so W averages the
other two vertices and each step s scales the offsets from the centroid by 1 - 1.5 s; the lone vertex
has no neighbour and stays."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.mesh import Mesh
from app.core.smoothing import averaging_operator, taubin

TRIANGLE = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, np.sqrt(3.0), 0.0]])
LONE = np.array([[5.0, 4.0, 3.0]])


def _mesh() -> Mesh:
    return Mesh(np.vstack([TRIANGLE, LONE]), np.array([[0, 1, 2]], np.int64))


@pytest.mark.parametrize("weights", ["intrinsic", "cotangent"])
def test_weights_of_a_lone_triangle_and_a_vertex_in_no_face(weights):
    w, has = averaging_operator(_mesh(), weights)  # every cotangent weight is cot 60° / 2 < 1 per row
    assert has.tolist() == [True, True, True, False]
    expected = np.zeros((4, 4))
    expected[:3, :3] = 0.5
    np.fill_diagonal(expected, 0.0)
    assert np.allclose(w.toarray(), expected, atol=1e-12)


@pytest.mark.parametrize("weights", ["intrinsic", "cotangent"])
def test_one_pair_of_steps_shrinks_the_triangle_about_its_centroid_and_leaves_the_lone_vertex(weights):
    mesh = _mesh()
    out = taubin(mesh, 2, weights)  # λ = 0.5, then μ = -0.53
    centroid = TRIANGLE.mean(axis=0)
    factor = (1 - 1.5 * 0.5) * (1 - 1.5 * -0.53)
    assert np.allclose(out.vertices[:3], centroid + factor * (TRIANGLE - centroid), atol=1e-10)
    assert np.array_equal(out.vertices[3:], LONE)
    assert np.array_equal(out.faces, mesh.faces)
    one = taubin(mesh, 1, weights).vertices  # a single λ step
    assert np.allclose(one[:3], centroid + (1 - 1.5 * 0.5) * (TRIANGLE - centroid), atol=1e-10)
    four = taubin(mesh, 4, weights).vertices  # W from the input geometry: the same factor again
    assert np.allclose(four[:3], centroid + factor**2 * (TRIANGLE - centroid), atol=1e-10)
