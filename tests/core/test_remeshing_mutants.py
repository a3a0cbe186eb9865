"""Remeshing guards (issue 15 mutation pass): a small surface is remeshed like a large one, and a
remesher result outside the vertex-count or area band leaves the input as it was."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.mesh import Mesh
from app.core.remeshing import edge_length, isotropic_remesh


def _sphere(radius: float = 1.0) -> Mesh:
    s = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    return Mesh(np.asarray(s.vertices, float), np.asarray(s.faces, np.int64))


@pytest.mark.parametrize("radius", [0.01, 1.0, 100.0])
def test_remeshing_does_not_depend_on_the_scale(radius: float):
    mesh = _sphere(radius)
    out = isotropic_remesh(mesh, 300)
    assert out is not mesh
    assert 150 <= out.n_vertices <= 600
    assert np.allclose(np.linalg.norm(out.vertices, axis=1), radius, rtol=0.02)
    assert out.area() == pytest.approx(mesh.area(), rel=0.05)


def _patched(monkeypatch, change):
    import gpytoolbox

    real = gpytoolbox.remesh_botsch
    monkeypatch.setattr(gpytoolbox, "remesh_botsch", lambda v, f, **kw: change(real, v, f, kw))


def test_too_few_vertices_from_the_remesher_keep_the_input(monkeypatch):
    # the remesher asked for edges twice as long: about a quarter of the target's vertices
    _patched(monkeypatch, lambda real, v, f, kw: real(v, f, **{**kw, "h": 2 * kw["h"]}))
    mesh = _sphere()
    assert isotropic_remesh(mesh, 600) is mesh


def test_a_result_of_another_area_keeps_the_input(monkeypatch):
    def grown(real, v, f, kw):
        v2, f2 = real(v, f, **kw)
        return 1.2 * v2, f2  # area x 1.44: outside the 20 % band, every vertex finite

    _patched(monkeypatch, grown)
    mesh = _sphere()
    assert isotropic_remesh(mesh, 300) is mesh


@pytest.mark.parametrize("target", [81, 324])
def test_a_vertex_count_at_either_end_of_the_band_is_accepted(monkeypatch, target: int):
    fixed = trimesh.creation.icosphere(subdivisions=2)  # 162 vertices = 2 x 81 = 0.5 x 324
    _patched(monkeypatch, lambda real, v, f, kw: (np.array(fixed.vertices), np.array(fixed.faces)))
    out = isotropic_remesh(_sphere(), target)
    assert out.n_vertices == 162
    assert np.array_equal(out.vertices, fixed.vertices)


@pytest.mark.parametrize("fraction, kept", [(1.1e-3, True), (0.9e-3, False)])
def test_a_face_is_a_sliver_below_one_thousandth_of_the_target_triangle(monkeypatch, fraction, kept):
    # face 0 of the remesher's output split at p: (a, b, p) gets `fraction` of the target triangle
    def split(real, v, f, kw):
        v2, f2 = real(v, f, **kw)
        a, b, c = f2[0]
        tri = np.linalg.norm(np.cross(v2[b] - v2[a], v2[c] - v2[a])) / 2
        w = fraction * np.sqrt(3.0) / 4.0 * kw["h"] ** 2 / tri
        p = (1 - w) / 2 * (v2[a] + v2[b]) + w * v2[c]
        n = len(v2)
        return np.vstack([v2, p]), np.vstack([f2[1:], np.array([[a, b, n], [b, c, n], [c, a, n]], f2.dtype)])

    _patched(monkeypatch, split)
    mesh = _sphere()
    out = isotropic_remesh(mesh, 300)
    assert out is not mesh
    sliver = fraction * np.sqrt(3.0) / 4.0 * edge_length(mesh.area(), 300) ** 2
    smallest = out.face_areas().min()
    if kept:
        assert smallest == pytest.approx(sliver, rel=1e-6)
    else:
        assert smallest > sliver / fraction * 1e-3  # nothing under the threshold is left
