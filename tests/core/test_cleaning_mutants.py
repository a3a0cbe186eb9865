"""Validation and cleaning at their thresholds (issue 15 mutation pass): tolerances relative to the
mesh's size, hit exactly or on either side."""

from __future__ import annotations

import numpy as np
import pytest

from app.core import cleaning
from app.core.meshdata import InvalidMeshError, Mesh

TETRA = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
TETRA_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)


def with_sliver(height: float) -> Mesh:
    """The unit tetrahedron and a sliver on its edge 0-1 of area height / 2 (largest side 1)."""
    v = np.vstack([TETRA, [[0.5, height, 0.0]]])
    return Mesh(v, np.vstack([TETRA_FACES, [[0, 1, 4]]]))


@pytest.mark.parametrize(("height", "kept"), [(2.4e-14, True), (1.6e-14, False)])
def test_a_face_is_degenerate_below_1e_14_of_the_squared_largest_side(height, kept):
    out = cleaning.clean(with_sliver(height))  # area 1.2e-14 and 0.8e-14
    assert out.n_faces == (5 if kept else 4)
    assert out.n_vertices == (5 if kept else 4)


@pytest.mark.parametrize(("height", "accepted"), [(2.4e-12, True), (1.6e-12, False)])
def test_validate_refuses_a_total_area_below_1e_12_of_the_squared_extent(height, accepted):
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, height, 0.0], [0.25, 0.0, 0.0]])
    f = np.array([[0, 1, 2], [0, 1, 3]], np.int64)  # areas height / 2 and 0
    if accepted:
        assert cleaning.validate(v, f).n_faces == 2
    else:
        with pytest.raises(InvalidMeshError, match="zero total area"):
            cleaning.validate(v, f)


def test_a_face_of_exactly_the_degenerate_area_is_dropped():
    assert cleaning.clean(with_sliver(2e-14)).n_faces == 4  # area 1e-14 x 1²: not above it


def test_the_degenerate_threshold_follows_the_largest_side_not_the_coordinates():
    # moved to x in [10, 11]: the largest side is still 1, the coordinates span 11
    moved = with_sliver(2.4e-14)
    moved = Mesh(moved.vertices + [10.0, 0.0, 0.0], moved.faces)
    assert cleaning.clean(moved).n_faces == 5


def test_too_few_faces_left_is_refused_with_the_count():
    with pytest.raises(InvalidMeshError) as info:
        cleaning.clean(Mesh(TETRA, TETRA_FACES[:3]))
    assert str(info.value) == "the mesh has too few non-degenerate faces (3 < 4)"


def _square_and_triangle(small_area: float) -> Mesh:
    """A flat square of four triangles (area 400) and, apart, one triangle of area small_area."""
    square = np.array([[0, 0, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0], [-10, -10, 0]], np.float64)
    small = np.array([[20, 0, 5], [21, 0, 5], [20, 2 * small_area, 5]], np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [5, 6, 7]], np.int64)
    return Mesh(np.vstack([square, small]), faces)


def test_a_piece_of_exactly_one_percent_of_the_largest_area_is_kept():
    assert cleaning.clean(_square_and_triangle(4.0)).n_faces == 5  # 0.01 x 400 == 4.0 exactly
    assert cleaning.clean(_square_and_triangle(3.9)).n_faces == 4  # debris


def test_a_soup_of_small_pieces_says_how_many_faces_each_has():
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float64)
    vertices = np.vstack([quad + [3.0 * k, 0.0, 0.0] for k in range(3)])
    faces = np.vstack([np.array([[0, 1, 2], [0, 2, 3]]) + 4 * k for k in range(3)]).astype(np.int64)
    with pytest.raises(InvalidMeshError) as info:
        cleaning.clean(Mesh(vertices, faces))
    assert str(info.value) == (
        "the mesh is a triangle soup: its 6 faces form 3 separate pieces (at most 2 faces each),"
        " with no surface joining them; export it as a connected (welded) surface"
    )


def test_a_soup_of_single_triangles_says_a_single_face_each():
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float64)
    vertices = np.vstack([tri + [3.0 * k, 0.0, 0.0] for k in range(4)])
    faces = np.arange(12, dtype=np.int64).reshape(4, 3)
    with pytest.raises(InvalidMeshError) as info:
        cleaning.clean(Mesh(vertices, faces))
    assert str(info.value) == (
        "the mesh is a triangle soup: its 4 faces form 4 separate pieces (a single face each),"
        " with no surface joining them; export it as a connected (welded) surface"
    )
