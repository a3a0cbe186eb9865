"""Batched ICP and Procrustes fits of the variant verification: the same answers as one at a time,
known motions recovered, handedness kept."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from app.core.variants.align import Similarity, det3, icp, icp_batch, umeyama, umeyama_batch


@pytest.fixture(scope="module")
def cloud() -> np.ndarray:
    """(2048, 3) an anisotropic Gaussian cloud: no symmetry a fit could slip along."""
    return np.random.default_rng(3).normal(size=(2048, 3)) * [1.0, 0.6, 0.3]


def test_umeyama_batch_is_umeyama_set_by_set(random_rotation) -> None:
    rng = np.random.default_rng(0)
    src = rng.normal(size=(3, 50, 3))
    dst = np.stack([2.5 * s @ random_rotation(i).T + [1.0, -2.0, 0.5] + rng.normal(scale=0.01, size=s.shape)
                    for i, s in enumerate(src)])
    mirrored = np.array([False, True, False])
    rot, scale, shift = umeyama_batch(src, dst, mirrored, with_scale=True)
    for i in range(3):
        one = umeyama(src[i], dst[i], mirrored=bool(mirrored[i]))
        np.testing.assert_allclose(rot[i], one.rotation, atol=1e-12)
        assert scale[i] == pytest.approx(one.scale, rel=1e-12)
        np.testing.assert_allclose(shift[i], one.translation, atol=1e-12)
    assert np.linalg.det(rot[1]) == pytest.approx(-1.0) and np.linalg.det(rot[0]) == pytest.approx(1.0)
    assert scale[0] == pytest.approx(2.5, rel=1e-2)  # the exact fit, up to the noise


def test_icp_batch_recovers_a_known_motion_and_keeps_handedness(cloud, random_rotation) -> None:
    turn = Similarity(1.0, random_rotation(1), np.zeros(3))
    rotation = Rotation.from_rotvec([0.08, -0.05, 0.06]).as_matrix()  # a small turn: ICP's basin
    shift = np.array([0.02, -0.01, 0.03])
    source = (cloud[:300] - shift) @ rotation  # target = rotation @ source + shift
    flip = Similarity(1.0, np.diag([1.0, 1.0, -1.0]), np.zeros(3))
    starts = [Similarity(1.0, np.eye(3), np.zeros(3)), flip, turn]
    fits, costs = icp_batch(source, cKDTree(cloud), cloud, starts, iterations=30)
    np.testing.assert_allclose(fits[0].rotation, rotation, atol=1e-9)
    np.testing.assert_allclose(fits[0].translation, shift, atol=1e-9)
    assert costs[0] < 1e-9
    assert fits[1].mirrored and costs[1] > 0.01  # a mirrored start stays mirrored and cannot fit
    assert costs.argmin() == 0


def test_icp_batch_equals_separate_runs(cloud, random_rotation) -> None:
    source = cloud[::7] @ random_rotation(4).T
    tree = cKDTree(cloud)
    starts = [random_rotation(i) for i in range(5)] + [random_rotation(9) @ np.diag([1.0, -1.0, 1.0])]
    fits, costs = icp_batch(source, tree, cloud, [Similarity(1.0, r, np.zeros(3)) for r in starts],
                            iterations=8, with_scale=True)
    for start, fit, cost in zip(starts, fits, costs, strict=True):
        one, one_cost = icp(source, tree, cloud, start, iterations=8, with_scale=True)
        np.testing.assert_allclose(fit.rotation, one.rotation, atol=1e-12)
        assert fit.scale == pytest.approx(one.scale, rel=1e-12) and cost == pytest.approx(one_cost, rel=1e-12)
        assert fit.mirrored == (np.linalg.det(start) < 0)


@pytest.mark.parametrize("mirror", [False, True])
def test_the_fine_fit_of_the_rough_hypotheses_recovers_a_known_similarity(random_rotation, mirror) -> None:
    """relate's fine fit from the best 2 rough fits of each handedness (the 2 that survive its first
    rounds go on): a hull rotated, scaled by 25.4, moved and perhaps mirrored is put back on itself."""
    import importlib

    import trimesh

    from app.core.mesh import Mesh
    from app.core.variants import Prepared

    r = importlib.import_module("app.core.variants.relate")
    tm = trimesh.convex.convex_hull(np.random.default_rng(7).normal(size=(80, 3)) * [1.0, 0.7, 0.4])
    v = np.asarray(tm.vertices)
    moved = 25.4 * v @ random_rotation(3).T + [10.0, -4.0, 2.0]
    if mirror:
        moved[:, 0] *= -1.0
    a = Prepared(Mesh(v, np.asarray(tm.faces, np.int64)))
    b = Prepared(Mesh(moved, np.asarray(tm.faces, np.int64)[:, ::-1] if mirror else np.asarray(tm.faces)))
    ranked = r._hypotheses(a, b, r.SCREEN_KEEP)
    rough = [f for _, f in ranked if not f.mirrored][: r.REFINE]
    rough += [f for _, f in ranked if f.mirrored][: r.REFINE]
    assert len(rough) == 4
    _, fit, _ = r._fine_fit(a, b, rough)
    assert fit.mirrored == mirror and fit.scale == pytest.approx(25.4, rel=1e-3)
    # sample-to-sample ICP: within a sample spacing's fraction (a wrong turn is off by tens of per cent)
    assert np.abs(fit.apply(v) - moved).max() < 0.01 * b.diagonal


def test_det3_is_the_determinant(random_rotation) -> None:
    """By hand: a diagonal matrix, a shear (det 1) and a swap of two rows (det -1); then random matrices
    and rotations against np.linalg.det, the sign of a mirrored rotation included."""
    by_hand = np.array([np.diag([2.0, 3.0, 0.5]), [[1.0, 4.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                        [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    np.testing.assert_allclose(det3(by_hand), [3.0, 1.0, -1.0], atol=1e-15)
    m = np.random.default_rng(1).normal(size=(20, 3, 3))
    np.testing.assert_allclose(det3(m), np.linalg.det(m), rtol=1e-12, atol=1e-12)
    turns = np.array([random_rotation(i) for i in range(4)])
    mirrored = turns * np.array([1.0, 1.0, -1.0])  # a column flipped: det -1
    assert (det3(turns) > 0).all() and (det3(mirrored) < 0).all()


def test_the_start_as_they_lie_is_no_turn_at_all(random_rotation) -> None:
    """as_they_lie() is the rotation that to_world turns into no turn at all, proper, whatever the two
    frames; the axes' hypotheses are still the 8 sign choices (no degenerate axes here)."""
    from app.core.variants.align import Frame, as_they_lie, hypotheses, to_world

    rng = np.random.default_rng(5)
    fa = Frame(rng.normal(size=3), 2.0, random_rotation(1), np.array([3.0, 2.0, 1.0]))
    fb = Frame(rng.normal(size=3), 0.5, random_rotation(2), np.array([3.0, 2.1, 0.9]))
    lie = as_they_lie(fa, fb)
    world = to_world(fa, fb, Similarity(1.0, lie, np.zeros(3)))
    np.testing.assert_allclose(world.rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(lie) == pytest.approx(1.0)
    assert len(hypotheses(fa, fb)) == 8
