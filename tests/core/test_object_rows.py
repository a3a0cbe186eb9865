"""app.core.object_rows: which objects of a file get rows, and how rows merge into one hit a model."""

from __future__ import annotations

import numpy as np
import trimesh

from app.core.meshdata import Mesh
from app.core.object_rows import distinct_objects, merge_rows


def _mesh(*parts: trimesh.Trimesh) -> Mesh:
    joined = trimesh.util.concatenate(list(parts))
    return Mesh(np.asarray(joined.vertices, np.float64), np.asarray(joined.faces, np.int64))


def _at(mesh: trimesh.Trimesh, x: float, scale: float = 1.0) -> trimesh.Trimesh:
    out = mesh.copy()
    out.apply_scale(scale)
    out.apply_translation([x, 0.0, 0.0])
    return out


def test_a_single_object_has_no_rows_beyond_its_whole():
    assert distinct_objects(_mesh(trimesh.creation.icosphere(3))) == []


def test_copies_share_a_row_and_other_objects_get_their_own_largest_first():
    box = trimesh.creation.box((1.0, 0.6, 0.3)).subdivide().subdivide()
    ball = trimesh.creation.icosphere(3, radius=0.5)
    rows = distinct_objects(_mesh(_at(box, 0), _at(ball, 3), _at(box, 6), _at(box, 9, scale=1.5)))
    # the rescaled box is a copy too: the fingerprint and the BoF are both scale-free
    assert [(r.part, r.copies) for r in rows] == [(1, 3), (2, 1)]
    assert rows[0].mesh.n_faces == box.faces.shape[0] and rows[1].mesh.n_faces == ball.faces.shape[0]
    total = 2 * box.area + (1.5**2) * box.area + ball.area
    assert np.isclose(rows[0].share, (1.5**2) * box.area / total)  # the largest copy stands for them
    assert np.isclose(rows[1].share, ball.area / total)


def test_rows_are_capped_and_specks_left_out():
    ball = trimesh.creation.icosphere(2)
    shapes = [trimesh.creation.box((1.0, 0.2 + 0.25 * i, 0.3)).subdivide().subdivide() for i in range(5)]
    speck = trimesh.creation.icosphere(1, radius=0.05)  # 0.3 % of the largest's area: trim
    mesh = _mesh(ball, *(_at(s, 3 * (i + 1)) for i, s in enumerate(shapes)), _at(speck, 30))
    assert len(distinct_objects(mesh)) == 6
    assert len(distinct_objects(mesh, max_rows=3)) == 3


def test_rows_merge_into_one_entry_a_model_at_its_least_distance():
    dist, ids, parts = merge_rows(np.array([0.5, 1.0, 2.0]), np.array([7, 8, 9]),
                                  np.array([0.25, 1.5, 0.5]), np.array([9, 8, 4]), np.array([2, 1, 1]))
    # 9 through its object row 2 (0.25 < 2.0); 8 keeps its whole (1.0 < 1.5); 4 has only an object row;
    # 7 and 4 tie at 0.5: the lower model id first
    assert ids.tolist() == [9, 4, 7, 8] and parts.tolist() == [2, 1, 0, 0]
    assert dist.tolist() == [0.25, 0.5, 0.5, 1.0] and dist.dtype == np.float32
    none = np.zeros(0, np.int64)
    empty = merge_rows(np.array([1.0]), np.array([3]), np.zeros(0), none, none)
    assert empty[1].tolist() == [3] and empty[2].tolist() == [0]


def test_flat_trim_never_crowds_the_parts_out():
    """70 large two-face quads (trim: fewer faces than a surface needs) beside a torus and a cube: the
    quads are neither rows nor the yardstick of the area share, and the cube (12 faces) is a part."""
    quad = trimesh.Trimesh([[0, 0, 0], [3, 0, 0], [3, 3, 0], [0, 3, 0]], [[0, 1, 2], [0, 2, 3]])
    torus = trimesh.creation.torus(1.0, 0.3)
    parts = [_at(quad, 4 * i) for i in range(70)] + [_at(torus, 300), _at(trimesh.creation.box(), 310)]
    rows = distinct_objects(_mesh(*parts))
    assert [r.mesh.n_faces for r in rows] == [torus.faces.shape[0], 12]


def test_many_copies_do_not_crowd_out_a_smaller_distinct_part():
    box = trimesh.creation.box((1.0, 0.6, 0.3)).subdivide()
    ball = trimesh.creation.icosphere(2, radius=0.3)  # smaller than every copy of the box
    rows = distinct_objects(_mesh(*(_at(box, 2 * i) for i in range(100)), _at(ball, 250)))
    assert [(r.copies, r.mesh.n_faces) for r in rows] == [(100, box.faces.shape[0]), (1, ball.faces.shape[0])]
