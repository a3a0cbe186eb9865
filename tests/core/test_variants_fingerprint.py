"""The variant fingerprint, the surface integrals under it, and the candidate index."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.mesh import Mesh
from app.core.variants import fingerprint
from app.core.variants.index import FingerprintIndex
from app.core.variants.surface import closest_on_triangles, moments, objects
from tests.variant_meshes import hull


def _hull(seed: int, n: int = 60) -> Mesh:
    """A random convex hull: no symmetry, so a mirror image is not a rotation of it."""
    return hull(seed, n)


def test_moments_of_a_unit_square_by_hand() -> None:
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    square = Mesh(corners, np.array([[0, 1, 2], [0, 2, 3]]))
    m = moments(square)
    assert m.area == pytest.approx(1.0)
    np.testing.assert_allclose(m.centroid, [0.5, 0.5, 0.0])
    np.testing.assert_allclose(m.cov, np.diag([1 / 12, 1 / 12, 0.0]), atol=1e-12)  # variance of U(0, 1)


def test_moments_of_a_sphere_approach_r2_over_3() -> None:
    tm = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    m = moments(Mesh(np.asarray(tm.vertices), np.asarray(tm.faces, np.int64)))
    np.testing.assert_allclose(np.diag(m.cov), 4.0 / 3.0, rtol=5e-3)  # E[x^2] = r^2 / 3 on the sphere
    assert m.area == pytest.approx(4 * np.pi * 4.0, rel=5e-3)


def test_closest_point_on_triangle_regions() -> None:
    a, b, c = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.0, 1, 0])
    # above the face, beyond corner a, beyond corner b, beside edge ab, beside edge bc
    points = np.array([[0.2, 0.2, 3.0], [-1.0, -1.0, 0.0], [2.0, -0.5, 1.0], [0.5, -1.0, 0.0],
                       [1.0, 1.0, 0.0]])
    n = len(points)
    got = closest_on_triangles(points, np.tile(a, (n, 1)), np.tile(b, (n, 1)), np.tile(c, (n, 1)))
    expected = [[0.2, 0.2, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.5, 0.5, 0.0]]
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_fingerprint_ignores_order_motion_scale_and_mirror(random_rotation) -> None:
    mesh = _hull(1)
    fp = fingerprint(mesh)
    rng = np.random.default_rng(0)
    perm = rng.permutation(mesh.n_vertices)
    reordered = Mesh(mesh.vertices[perm], np.argsort(perm)[mesh.faces][rng.permutation(mesh.n_faces)])
    moved = Mesh(25.4 * mesh.vertices @ random_rotation(3).T + [10, -4, 2], mesh.faces)
    mirrored = Mesh(mesh.vertices * [1, -1, 1], mesh.faces[:, ::-1])
    # exact moments; the sampled quantiles move by sampling noise only (4096 samples)
    for other in (reordered, moved, mirrored):
        assert np.linalg.norm(fingerprint(other) - fp) < 0.05
        np.testing.assert_allclose(fingerprint(other)[:7], fp[:7], rtol=1e-4, atol=1e-6)


def test_third_moment_matches_dense_sampling() -> None:
    from app.core.variants.fingerprint import _third_moments
    from app.core.variants.surface import faces_of, sample_surface

    mesh = _hull(4)
    m = moments(mesh)
    _, axes = m.axes()
    points, _, _ = sample_surface(mesh, 400_000, seed=3)
    sampled = (((points - m.centroid) @ axes) ** 3).mean(axis=0)
    np.testing.assert_allclose(_third_moments(faces_of(mesh), m, axes), sampled, atol=0.01)


def test_volume_and_shared_face_arrays_by_hand() -> None:
    """A 1 x 2 x 3 box encloses 6 from any origin; the fingerprint from precomputed face arrays and
    moments is the fingerprint."""
    from app.core.variants.fingerprint import _signed_volume
    from app.core.variants.surface import faces_of

    box = trimesh.creation.box([1.0, 2.0, 3.0])
    mesh = Mesh(np.asarray(box.vertices) + [5.0, -2.0, 1.0], np.asarray(box.faces, np.int64))
    faces = faces_of(mesh)
    assert abs(_signed_volume(faces, np.zeros(3))) == pytest.approx(6.0)
    assert abs(_signed_volume(faces, np.array([40.0, 3.0, -7.0]))) == pytest.approx(6.0)
    np.testing.assert_allclose(faces.area.sum(), 22.0)  # 2 (1*2 + 1*3 + 2*3)
    np.testing.assert_array_equal(fingerprint(mesh, faces, moments(mesh, faces)), fingerprint(mesh))


def test_fingerprint_separates_different_shapes() -> None:
    box = trimesh.creation.box([1.0, 2.0, 3.0])
    sphere = trimesh.creation.icosphere(subdivisions=3)
    fb = fingerprint(Mesh(np.asarray(box.vertices), np.asarray(box.faces, np.int64)))
    fs = fingerprint(Mesh(np.asarray(sphere.vertices), np.asarray(sphere.faces, np.int64)))
    assert np.linalg.norm(fb - fs) > 0.3
    assert fs[3] == pytest.approx(1.0, rel=0.02)  # the volume term is 1 for a sphere
    assert fs[0] == pytest.approx(1.0, abs=0.01)  # and its moments are isotropic


def test_objects_split_a_plate_and_keep_a_single_body_whole() -> None:
    hull = _hull(2)
    shift = np.ptp(hull.vertices, axis=0)[0] * 1.5
    plate = Mesh(np.vstack([hull.vertices + [i * shift, 0, 0] for i in range(3)]),
                 np.vstack([hull.faces + i * hull.n_vertices for i in range(3)]))
    parts = objects(plate)
    assert len(parts) == 3
    assert all(p.n_faces == hull.n_faces for p in parts)
    assert objects(hull) == [hull]
    # two pieces whose boxes overlap (an eye inside a head) are one object
    inner = Mesh(hull.vertices * 0.1, hull.faces)
    nested = Mesh(np.vstack([hull.vertices, inner.vertices]),
                  np.vstack([hull.faces, inner.faces + hull.n_vertices]))
    assert len(objects(nested)) == 1


def test_index_candidates_nearest_first_and_hnsw_agrees_with_flat() -> None:
    rng = np.random.default_rng(0)
    data = rng.random((3000, 17)).astype(np.float32)
    keys = np.arange(3000) // 2  # two rows per key, as a model with one object part
    flat, hnsw = FingerprintIndex(), FingerprintIndex(exact_below=0)
    flat.build(keys, data)
    hnsw.build(keys, data)
    queries = data[:50] + 0.001
    got_flat, _ = flat.search(queries, 8)
    got_hnsw, _ = hnsw.search(queries, 8)
    assert (got_flat[:, 0] == keys[:50]).all()
    agree = np.mean([len(set(a) & set(b)) / len(set(a)) for a, b in zip(got_flat, got_hnsw, strict=True)])
    assert agree > 0.9
    assert flat.nearest(queries[:1], k=4, radius=0.01) == [(0, pytest.approx(0.001 * 17**0.5, rel=1e-3))]
    grown = FingerprintIndex(exact_below=2000)  # rows added in steps, past the switch to a graph
    for start in range(0, 3000, 1000):
        grown.add(keys[start:start + 1000], data[start:start + 1000])
    got_grown, _ = grown.search(queries, 8)
    assert len(grown) == 3000 and (got_grown[:, 0] == keys[:50]).all()
    assert FingerprintIndex().nearest(queries[:1]) == []


def test_shortlist_verifies_every_near_copy_and_a_few_others() -> None:
    from app.core.variants.collection import VERIFY, shortlist

    rng = np.random.default_rng(1)
    base = rng.random(17).astype(np.float32)
    near = base + rng.normal(scale=0.001, size=(9, 17)).astype(np.float32)  # 9 copies of one part
    far = base + rng.normal(scale=0.05, size=(20, 17)).astype(np.float32)  # 20 looser neighbours
    index = FingerprintIndex()
    index.build(np.arange(29), np.vstack([near, far]))
    got = shortlist(index, base[None])
    assert set(got[:9]) == set(range(9)) and len(got) == 9  # all the copies, past the cap of VERIFY
    assert len(shortlist(index, far[:1], exclude=9)) == VERIFY


def test_index_rows_of_a_key() -> None:
    index = FingerprintIndex()
    vectors = np.arange(4 * 17, dtype=np.float32).reshape(4, 17)
    index.build(np.array([1, 1, 2]), vectors[:3])
    index.add(np.array([1]), vectors[3:])
    np.testing.assert_array_equal(index.rows(1), vectors[[0, 1, 3]])  # out of order: by a scan
    assert index.rows(5).shape == (0, 17)
    ordered = FingerprintIndex()
    ordered.build(np.array([1, 1, 2]), vectors[:3])
    ordered.add(np.array([4, 4]), vectors[2:])
    np.testing.assert_array_equal(ordered.rows(1), vectors[:2])  # in order: by bisection
    np.testing.assert_array_equal(ordered.rows(4), vectors[2:])
    assert ordered.rows(3).shape == (0, 17) and ordered.rows(0).shape == (0, 17)
