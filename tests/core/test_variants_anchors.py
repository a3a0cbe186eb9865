"""Anchors for the same-triangles test (app/core/variants/anchors.py): per-vertex descriptors are
unchanged by a similarity, a mirror and a renumbering, and they let relate() find a renumbered copy
of a rotationally symmetric shape whose surface fit cannot choose the turn."""

from __future__ import annotations

import collections
import importlib

import numpy as np
import pytest

from app.core.mesh import Mesh
from app.core.variants import Prepared, relate
from app.core.variants.anchors import anchored_fits, descriptors


def _tube(seed: int, segments: int = 24, rows: int = 6) -> Mesh:
    """A closed circular tube (caps fanned to their centres) whose quads are split on random
    diagonals: the vertices are symmetric under 24 turns, the triangles under none."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    z = np.linspace(0, 3.0, rows)
    v = np.array([[np.cos(a), np.sin(a), h] for h in z for a in t] + [[0, 0, 0], [0, 0, 3.0]])
    faces = []
    for r in range(rows - 1):
        for s in range(segments):
            a, b = r * segments + s, r * segments + (s + 1) % segments
            c, d = a + segments, b + segments
            faces += [[a, b, d], [a, d, c]] if rng.random() < 0.5 else [[a, b, c], [b, d, c]]
    lo, hi, top = rows * segments, rows * segments + 1, (rows - 1) * segments
    for s in range(segments):
        faces += [[lo, (s + 1) % segments, s], [hi, top + s, top + (s + 1) % segments]]
    return Mesh(v, np.array(faces, np.int64))


def _copy(mesh: Mesh, rng: np.random.Generator, mirror: bool) -> tuple[Mesh, np.ndarray]:
    """Turned, scaled by 2.5, moved, perhaps mirrored, vertices and faces renumbered; and the new
    number of each old vertex."""
    q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    q *= np.sign(np.linalg.det(q))
    v = 2.5 * mesh.vertices @ q.T + 1.0
    faces = mesh.faces
    if mirror:
        v[:, 0] *= -1.0
        faces = faces[:, ::-1]
    perm = rng.permutation(mesh.n_vertices)
    new = np.empty_like(perm)
    new[perm] = np.arange(len(perm))
    return Mesh(v[perm], new[faces][rng.permutation(len(faces))]), new


def test_descriptors_by_hand_and_unchanged_by_a_similarity_and_a_renumbering() -> None:
    base = _tube(0)
    d = descriptors(Prepared(base))
    neighbours = collections.defaultdict(set)
    for f in base.faces:
        for i in range(3):
            neighbours[f[i]] |= {f[(i + 1) % 3], f[(i + 2) % 3]}
    degree = np.array([len(neighbours[i]) for i in range(base.n_vertices)])
    assert np.array_equal(d[:, 0], degree)
    assert np.allclose(d[:, 5] * 8, [sum(degree[j] for j in neighbours[i]) for i in range(len(degree))])
    assert d[-1, 0] == 24 and d[-1, 2] == pytest.approx(d[-1, 4])  # a cap centre: 24 equal spokes
    for mirror in (False, True):
        copy, new = _copy(base, np.random.default_rng(3), mirror)
        assert np.allclose(descriptors(Prepared(copy))[new], d, atol=1e-9)


@pytest.mark.parametrize("mirror", [False, True])
def test_a_renumbered_copy_of_a_symmetric_shape_is_found_exact(mirror) -> None:
    """Without the anchors the surface fit ends on a turn where the vertices meet but the triangles
    do not (`retriangulated`); with them, `rescaled` or `mirrored` with the factor."""
    rel = importlib.import_module("app.core.variants.relate")
    base = _tube(1)
    copy, _ = _copy(base, np.random.default_rng(51), mirror)
    a, b = Prepared(copy), Prepared(base)
    assert len(anchored_fits(a, b)) >= 2
    ev = relate(a, b)
    assert ev.relation == ("mirrored" if mirror else "rescaled") and ev.scale == pytest.approx(0.4, rel=1e-6)
    saved = rel.anchored_fits
    try:
        rel.anchored_fits = lambda a, b: []
        assert relate(Prepared(copy), Prepared(base)).relation == "retriangulated"  # the premise
    finally:
        rel.anchored_fits = saved


def test_no_anchors_between_different_triangulations() -> None:
    """Two tubes split on other diagonals share few unambiguous vertices; whatever anchors they
    offer, the exact test still refuses them: retriangulated, never an exact relation."""
    a, b = Prepared(_tube(2)), Prepared(_tube(3))
    assert relate(a, b).relation == "retriangulated"
