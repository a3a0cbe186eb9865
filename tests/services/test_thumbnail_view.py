"""The thumbnail's canonical view (issue 14 item 4): principal axes, the side with the most silhouette,
upright: a z-up quadruped is drawn standing, from the side, however it is turned."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from app.services.thumbnail_view import canonical_rotation
from app.services.thumbnails import render_rgba


def quadruped() -> trimesh.Trimesh:
    """z-up: a body 4 long (x), 1 wide (y), 1 high, on four thin legs 1.6 long below it."""
    body = trimesh.creation.box(extents=[4.0, 1.0, 1.0])
    body.apply_translation([0, 0, 1.6 + 0.5])
    legs = []
    for x in (-1.6, 1.6):
        for y in (-0.35, 0.35):
            leg = trimesh.creation.box(extents=[0.2, 0.2, 1.6])
            leg.apply_translation([x, y, 0.8])
            legs.append(leg)
    return trimesh.util.concatenate([body, *legs])


def _legs_below(mesh: trimesh.Trimesh, rot: np.ndarray, world_up: np.ndarray) -> None:
    up = rot[1]
    assert up @ world_up > 0.95, f"up {up} is not the animal's up {world_up}"


def test_a_rotation_not_a_mirror() -> None:
    m = quadruped()
    r = canonical_rotation(m.vertices, m.faces)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(r) == pytest.approx(1.0)


def test_z_up_file_is_drawn_standing_and_from_the_side() -> None:
    m = quadruped()
    r = canonical_rotation(m.vertices, m.faces)
    _legs_below(m, r, np.array([0.0, 0.0, 1.0]))
    assert abs(r[2] @ np.array([0.0, 1.0, 0.0])) > 0.95  # looking across the body: the largest silhouette


@pytest.mark.parametrize("spin", [0.0, 1.2, 2.7, 4.5])
def test_any_orientation_without_a_hint_is_stood_up_by_its_legs(spin: float) -> None:
    m = quadruped()
    # turn the animal so that neither +y nor +z is near any of its axes: only its shape can tell
    target = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)
    turn, _ = Rotation.align_vectors([target], [[0.0, 0.0, 1.0]])
    rot = (Rotation.from_rotvec(target * spin) * turn).as_matrix()
    assert np.abs(rot.T[:, 1:]).max() < 0.85  # no body axis within ~30 degrees of +y or +z
    v = m.vertices @ rot.T
    world_up = rot @ np.array([0.0, 0.0, 1.0])
    r = canonical_rotation(v, m.faces)
    _legs_below(m, r, world_up)


def test_the_thumbnail_shows_legs_at_the_bottom() -> None:
    m = quadruped()
    alpha = render_rgba(m.vertices, m.faces, 128)[..., 3] > 0
    rows = np.flatnonzero(alpha.any(axis=1))
    top, bottom = rows.min(), rows.max()
    third = (bottom - top) // 3
    upper = alpha[top : top + third].mean()
    lower = alpha[bottom - third : bottom + 1].mean()
    assert lower < 0.5 * upper  # thin legs below, the solid body above
