"""Quadric edge collapse's face budget and vertex clustering's grid, cells, sides and rounds, on
hand-made meshes."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest
import trimesh

from app.core import decimation
from app.core.meshdata import Mesh


def _sphere(subdivisions: int = 2) -> Mesh:
    s = trimesh.creation.icosphere(subdivisions)
    return Mesh(np.asarray(s.vertices, np.float64), np.asarray(s.faces, np.int64))


# --- quadric -------------------------------------------------------------------------------------


@pytest.fixture
def fake_simplifier(monkeypatch):
    calls = []

    def simplify(vertices, faces, target_count, agg):
        calls.append((vertices, faces, target_count, agg))
        # float32 vertices and flat int32 faces: whatever the library gives, the Mesh is float64/int64
        return (vertices[:4] * 2.0).astype(np.float32), faces[:2].ravel()

    monkeypatch.setitem(sys.modules, "fast_simplification", types.SimpleNamespace(simplify=simplify))
    return calls


def test_quadric_asks_for_the_face_count_of_the_target_at_the_mesh_s_faces_per_vertex(fake_simplifier):
    mesh = _sphere(2)  # 162 vertices, 320 faces
    out = decimation.quadric(mesh, 50, 3.5)
    [(v, f, target_count, agg)] = fake_simplifier
    assert target_count == round(320 * 50 / 162) and agg == 3.5
    assert v.dtype == np.float64 and v.flags.c_contiguous and f.dtype == np.int32 and f.flags.c_contiguous
    np.testing.assert_array_equal(v, mesh.vertices)
    np.testing.assert_array_equal(f, mesh.faces)
    assert out.vertices.dtype == np.float64 and out.faces.dtype == np.int64 and out.faces.shape == (2, 3)
    np.testing.assert_array_equal(out.vertices, (mesh.vertices[:4] * 2.0).astype(np.float32))


def test_quadric_asks_for_at_least_one_face(fake_simplifier):
    decimation.quadric(_sphere(2), 0, 3.0)
    assert fake_simplifier[0][2] == 1


def test_quadric_leaves_a_mesh_already_at_or_below_the_budget(fake_simplifier):
    mesh = _sphere(2)
    assert decimation.quadric(mesh, 162, 3.0) is mesh  # 320 faces asked: all of them
    assert decimation.quadric(mesh, 500, 3.0) is mesh
    assert fake_simplifier == []


# --- face and vertex normals ---------------------------------------------------------------------


@pytest.mark.parametrize("chunk", [1, 2, 3, 7, 1 << 18])
def test_face_normals_by_chunks_are_the_cross_products(chunk):
    mesh = _sphere(1)
    v = mesh.vertices[mesh.faces]
    expected = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    np.testing.assert_allclose(decimation.face_normals(mesh, chunk=chunk), expected, rtol=0, atol=1e-15)


def test_vertex_normals_sum_the_normals_of_the_faces_around_each_vertex():
    mesh = Mesh(np.vstack([_sphere(1).vertices, [[5.0, 5.0, 5.0]]]), _sphere(1).faces)  # one lone vertex
    fn = decimation.face_normals(mesh)
    expected = np.zeros((mesh.n_vertices, 3))
    for face, normal in zip(mesh.faces, fn, strict=True):
        expected[face] += normal
    np.testing.assert_allclose(decimation.vertex_normal_sums(mesh, fn), expected, atol=1e-14)


# --- cells and clusters --------------------------------------------------------------------------


@pytest.mark.parametrize("h", [1.0, 0.5, 1e-7])  # 1e-7: over 2^62 cells in the box, the row sort
def test_cells_group_the_vertices_of_each_grid_cell_from_the_box_corner(h):
    v = np.array(
        [
            [0.1, 0.1, 0.1],
            [0.9, 0.2, 0.3],
            [1.1, 0.1, 0.1],
            [0.2, 0.3, 2.5],
            [1.5, 0.9, 0.0],
            [0.0, 0.0, 0.0],
            [0.2, 0.3, 2.5 + 1e-9],
        ]
    ) + [10.0, -4.0, 7.0]
    lo = v.min(axis=0)
    labels, first = decimation._cells(v, lo, h)
    assert labels.dtype == np.int64 and labels.shape == (len(v),)
    cells = [tuple(c) for c in np.floor((v - lo) / h).astype(int)]
    for i in range(len(v)):
        for j in range(len(v)):
            assert (labels[i] == labels[j]) == (cells[i] == cells[j])
    assert sorted(set(labels.tolist())) == list(range(len(first)))
    for label, index in enumerate(first):
        assert labels[index] == label and index == np.flatnonzero(labels == label).min()


def test_cells_past_2_62_are_told_apart_even_where_a_packed_key_would_wrap():
    # dims (1, 2^24 + 1, 2^40): packed, (0, 0, 0) and (0, 2^24, 0) would both be 0 modulo 2^64
    v = np.array([[0.0, 0.0, 0.0], [0.5, 2.0**24 + 0.5, 0.5], [0.5, 0.5, 2.0**40 - 0.5]])
    labels, first = decimation._cells(v, np.zeros(3), 1.0)
    assert len(set(labels.tolist())) == 3 and len(first) == 3


def test_clusters_split_a_cell_by_the_side_its_normals_face():
    v = np.array(
        [
            [0.1, 0.1, 0.1],
            [0.2, 0.2, 0.2],
            [0.3, 0.1, 0.2],
            [0.4, 0.4, 0.4],
            [1.5, 0.5, 0.5],
            [0.5, 0.5, 0.5],
            [0.6, 0.6, 0.6],
        ]
    )
    normals = np.array(
        [[0, 0, 1.0], [0, 0, -1.0], [0, 1.0, 0.1], [0.1, 0, -1.0], [0, 0, -1.0], [1.0, 0, 0], [0, 0, 0]]
    )
    labels, count = decimation._clusters(v, v.min(axis=0), 1.0, normals)
    # cell 0 holds vertices 0-3 and 5-6: 0 and 2 face the way vertex 0 does, 1 and 3 the other way; 5
    # (at right angles) and 6 (no normal) are not turned away, so they stay with 0
    assert count == 3
    assert (
        labels[0] == labels[2] == labels[5] == labels[6] != labels[1] == labels[3] != labels[4] != labels[0]
    )
    assert labels.dtype == np.int64 and sorted(set(labels.tolist())) == [0, 1, 2]
    plain, n = decimation._clusters(v, v.min(axis=0), 1.0, None)
    assert n == 2 and len(set(plain[[0, 1, 2, 3, 5, 6]].tolist())) == 1


def test_cluster_moves_each_vertex_to_its_cluster_mean_and_drops_collapsed_faces(monkeypatch):
    mesh = Mesh(
        np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [4, 0, 0], [5, 0, 0], [4, 1, 0]], np.float64),
        np.array([[0, 1, 2], [0, 3, 4], [3, 4, 5], [1, 4, 5], [2, 5, 0], [1, 0, 2]], np.int64),
    )
    groups = np.array([0, 1, 1, 2, 2, 3])  # 1 = 2 and 3 = 4
    monkeypatch.setattr(decimation, "_clusters", lambda v, lo, h, normals: (groups, 4))
    out = decimation.cluster(mesh, 4)
    np.testing.assert_allclose(out.vertices, [[0, 0, 0], [0.5, 0.5, 0], [4.5, 0, 0], [4, 1, 0]])
    # (0,1,1), (0,2,2), (2,2,3) and (1,0,1) collapse: a face with a repeated cluster goes, whichever corners
    np.testing.assert_array_equal(out.faces, [[1, 2, 3], [1, 3, 0]])


def test_cluster_corrects_the_cell_size_until_the_count_is_within_0_9_to_1_05_of_the_target(monkeypatch):
    counts = iter([400, 90, 105, 50])
    sizes: list[float] = []

    def fake(v, lo, h, normals):
        sizes.append(h)
        n = next(counts)
        return np.arange(len(v)) % n, n

    monkeypatch.setattr(decimation, "_clusters", fake)
    mesh = _sphere(3)
    area = mesh.area()
    decimation.cluster(mesh, 100)
    assert sizes[0] == pytest.approx(np.sqrt(area / 100))
    assert sizes[1] == pytest.approx(sizes[0] * 2.0)  # 400 clusters: cells twice as large
    assert len(sizes) == 2  # 90 is within the band (0.9 x 100 included)
    sizes.clear()
    counts = iter([106, 105])
    decimation.cluster(mesh, 100)
    assert len(sizes) == 2 and sizes[1] == pytest.approx(sizes[0] * np.sqrt(1.06))  # 105: included


def test_cluster_gives_up_correcting_after_the_rounds(monkeypatch):
    sizes: list[float] = []

    def fake(v, lo, h, normals):
        sizes.append(h)
        return np.arange(len(v)) % 10, 10

    monkeypatch.setattr(decimation, "_clusters", fake)
    decimation.cluster(_sphere(3), 100)
    assert len(sizes) == 1 + 6
    sizes.clear()
    decimation.cluster(_sphere(3), 100, rounds=2)
    assert len(sizes) == 3


def test_cluster_splits_sides_by_default_and_not_when_asked(monkeypatch):
    seen = []

    def fake(v, lo, h, normals):
        seen.append((lo, normals))
        return np.arange(len(v)) % 100, 100

    monkeypatch.setattr(decimation, "_clusters", fake)
    mesh = Mesh(_sphere(3).vertices + [3.0, -2.0, 1.0], _sphere(3).faces)
    decimation.cluster(mesh, 100)
    lo, normals = seen[-1]
    np.testing.assert_allclose(lo, mesh.vertices.min(axis=0))  # the grid starts at the box corner
    np.testing.assert_allclose(normals, decimation.vertex_normal_sums(mesh, decimation.face_normals(mesh)))
    decimation.cluster(mesh, 100, split_sides=False)
    assert seen[-1][1] is None


def test_cluster_to_one_vertex_starts_from_cells_of_the_whole_area(monkeypatch):
    sizes: list[float] = []

    def fake(v, lo, h, normals):
        sizes.append(h)
        return np.zeros(len(v), np.int64), 1

    monkeypatch.setattr(decimation, "_clusters", fake)
    mesh = _sphere(2)
    out = decimation.cluster(mesh, 1)
    assert sizes == [pytest.approx(np.sqrt(mesh.area()))]
    np.testing.assert_allclose(out.vertices, [mesh.vertices.mean(axis=0)], atol=1e-15)
