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


@pytest.mark.parametrize(("height", "accepted"), [(2.4e-12, True), (2e-12, False), (1.6e-12, False)])
def test_validate_refuses_a_total_area_below_1e_12_of_the_squared_extent(height, accepted):
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, height, 0.0], [0.25, 0.0, 0.0]])
    f = np.array([[0, 1, 2], [0, 1, 3]], np.int64)  # areas height / 2 and 0
    if accepted:
        assert cleaning.validate(v, f).n_faces == 2
    else:
        with pytest.raises(InvalidMeshError) as info:
            cleaning.validate(v, f)
        assert str(info.value) == "the mesh has zero total area (all faces are degenerate)"


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


@pytest.mark.parametrize(("piece", "faces", "count", "says"), [
    ([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], 3, "at most 2 faces each"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], 4, "a single face each"),
])
def test_a_soup_says_how_many_faces_each_piece_has(piece, faces, count, says):
    """`count` copies of a piece, 3 apart: no surface joins them."""
    piece, faces = np.array(piece, np.float64), np.array(faces, np.int64)
    vertices = np.vstack([piece + [3.0 * k, 0.0, 0.0] for k in range(count)])
    all_faces = np.vstack([faces + len(piece) * k for k in range(count)])
    with pytest.raises(InvalidMeshError) as info:
        cleaning.clean(Mesh(vertices, all_faces))
    assert str(info.value) == (
        f"the mesh is a triangle soup: its {len(all_faces)} faces form {count} separate pieces ({says}),"
        " with no surface joining them; export it as a connected (welded) surface"
    )


def test_the_weld_tolerance_follows_the_largest_side_not_the_coordinates():
    # a unit box at x = 100: two points 3e-8 apart are 3 tolerances apart (1e-8 x side 1), not a
    # fraction of a tolerance measured on the coordinates (101)
    v = np.array(
        [[100, 0, 0], [101, 0, 0], [100, 1, 0], [100, 0, 1], [100.5, 0.5, 0.5], [100.5, 0.5 + 3e-8, 0.5]]
    )
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 4], [1, 2, 5]], np.int64)
    welded, faces = cleaning.merge_vertices(v, f)
    assert len(welded) == 6
    np.testing.assert_array_equal(faces, f)


def test_cells_whose_hashes_collide_are_still_told_apart():
    # grid cells (54143351, 47652665, 0) and (25118083, 21502376, 47765211) share merge_vertices'
    # 64-bit hash (found by a birthday search); with a unit cell (tolerance 2^-26 of a side of 2^26)
    # each integer point is its own cell. P's copy is welded to P; Q stays apart.
    p, q = [54143351.0, 47652665.0, 0.0], [25118083.0, 21502376.0, 47765211.0]
    v = np.array([[0.0, 0.0, 0.0], [2.0**26, 0.0, 0.0], p, q, p])
    f = np.array([[0, 1, 2], [0, 1, 3], [1, 3, 4]], np.int64)
    welded, faces = cleaning.merge_vertices(v, f, tolerance=2.0**-26)
    np.testing.assert_array_equal(welded, v[:4])
    np.testing.assert_array_equal(faces, [[0, 1, 2], [0, 1, 3], [1, 3, 2]])


@pytest.mark.parametrize("offset", [0.0, 0.25e-8, 3.75, -1234.5])
def test_welding_is_the_same_wherever_the_mesh_is_moved(offset):
    # a unit box (tolerance 1e-8): the grid is anchored at its corner, so two points 0.2 tolerances
    # apart across a cell boundary stay apart and two 0.1 apart inside a cell meet, at any offset
    c = 1e-8
    v = np.array(
        [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [10.4 * c, 0.5, 0.5],
            [10.6 * c, 0.5, 0.5],
            [20.0 * c, 0.5, 0.25],
            [20.1 * c, 0.5, 0.25],
        ]
    ) + [offset, 0.0, 0.0]
    f = np.array([[0, 1, 2], [0, 1, 3], [1, 2, 4], [1, 2, 5], [1, 3, 6], [1, 3, 7]], np.int64)
    welded, faces = cleaning.merge_vertices(v, f)
    assert len(welded) == 7
    assert faces[5].tolist() == [1, 3, 6]  # 7 met 6


def test_faces_of_a_mesh_past_2_21_vertices_are_told_apart_exactly():
    # packed into 21 bits each, (1, 3, 5) and (1, 2, 2^21 + 5) would share a key
    faces = np.array([[1, 3, 5], [1, 2, 2**21 + 5], [5, 1, 3]], np.int64)
    assert cleaning.unique_face_index(faces, 2**21 + 6).tolist() == [0, 1]
    assert cleaning.unique_face_index(faces[[0, 2]], 2**21).tolist() == [0]


def test_faces_of_a_mesh_past_2_20_vertices_are_packed_without_overlap():
    # with 22 bits for the middle index, (1, 5, 2^20 + 10) and (0, 2^20 + 5, 2^20 + 10) would meet
    faces = np.array([[1, 5, 2**20 + 10], [0, 2**20 + 5, 2**20 + 10]], np.int64)
    assert cleaning.unique_face_index(faces, 2**20 + 11).tolist() == [0, 1]


def test_an_empty_vertex_array_is_refused_as_no_vertices():
    with pytest.raises(InvalidMeshError) as info:
        cleaning.validate(np.zeros((0, 3)), np.array([[0, 1, 2]]))
    assert str(info.value) == "the mesh has no vertices"


def _tetra_scaled(scale: float) -> np.ndarray:
    return TETRA * scale


@pytest.mark.parametrize(
    ("vertices", "faces", "message"),
    [
        (np.zeros((4, 2)), TETRA_FACES, "the mesh has no vertices"),
        (np.zeros((4, 3, 1)), TETRA_FACES, "the mesh has no vertices"),
        (TETRA, np.zeros((0, 3), np.int64), "the mesh has no faces (a point cloud is not a surface)"),
        (TETRA, np.array([[0, 1, 2, 3]]), "faces must be triangles"),
        (TETRA, np.array([0, 1, 2]), "faces must be triangles"),
        (
            np.vstack([TETRA[:3], [[np.nan, 0, 0]]]),
            TETRA_FACES,
            "the mesh has non-finite vertex coordinates (NaN or infinity)",
        ),
        (
            np.vstack([TETRA[:3], [[np.inf, 0, 0]]]),
            TETRA_FACES,
            "the mesh has non-finite vertex coordinates (NaN or infinity)",
        ),
        (TETRA, np.array([[0, 1, -1]]), "a face points at a vertex that does not exist"),
        (TETRA, np.array([[0, 1, 4]]), "a face points at a vertex that does not exist"),
        (TETRA[:3], np.array([[0, 1, 2]]), "the mesh has too few vertices (3 < 4)"),
        (
            _tetra_scaled(2e70),
            TETRA_FACES,
            "the coordinates are too large (up to 2e+70; at most 1e+70):"
            " scale the model down before exporting it",
        ),
        (
            _tetra_scaled(5e-71),
            TETRA_FACES,
            "the mesh is too small (it spans 5e-71; at least 1e-70): scale the model up before exporting it",
        ),
        (np.ones((4, 3)), TETRA_FACES, "the mesh has zero total area (all faces are degenerate)"),
    ],
)
def test_validate_names_the_first_problem_word_for_word(vertices, faces, message):
    with pytest.raises(InvalidMeshError) as info:
        cleaning.validate(vertices, faces)
    assert str(info.value) == message


def test_coordinates_of_exactly_the_bounds_are_accepted():
    assert cleaning.validate(_tetra_scaled(1e70), TETRA_FACES).n_vertices == 4
    assert cleaning.validate(_tetra_scaled(1e-70), TETRA_FACES).n_vertices == 4


def test_stray_points_do_not_set_the_scale():
    # a point in no face, far away and huge: the mesh itself is a unit tetrahedron
    v = np.vstack([TETRA, [[1e200, 0, 0]]])
    assert cleaning.validate(v, TETRA_FACES).n_vertices == 5
    tiny = np.vstack([TETRA * 1e-50, [[1.0, 1.0, 1.0]]])  # small faces beside a stray point at 1
    assert cleaning.validate(tiny, TETRA_FACES).n_vertices == 5


@pytest.mark.parametrize("scale", [1e-70, 1e70])
def test_a_mesh_at_the_coordinate_bounds_cleans_to_the_same_mesh_as_at_unit_scale(scale):
    # bug fix: the bounds were 1e-100 and 1e100, where areas (through their squares, ~ edge^4)
    # underflowed (a 1e-80 sphere lost faces as "degenerate", a 1e-90 one was "zero total area") or
    # overflowed (infinite areas at 1e80)
    import trimesh

    sphere = trimesh.creation.icosphere(3)
    unit = cleaning.clean(cleaning.validate(sphere.vertices, sphere.faces))
    scaled = cleaning.clean(cleaning.validate(sphere.vertices * scale, sphere.faces))
    np.testing.assert_array_equal(scaled.faces, unit.faces)
    assert scaled.area() == pytest.approx(unit.area() * scale * scale, rel=1e-12)


@pytest.mark.parametrize(("scale", "message"), [(1e-80, "too small"), (1e80, "too large")])
def test_a_mesh_past_the_bounds_is_refused_with_the_reason(scale, message):
    import trimesh

    sphere = trimesh.creation.icosphere(3)
    with pytest.raises(InvalidMeshError, match=message):
        cleaning.validate(sphere.vertices * scale, sphere.faces)


def test_too_few_vertices_counts_the_vertices():
    with pytest.raises(InvalidMeshError) as info:
        cleaning.validate(TETRA[:2], np.array([[0, 1, 1]]))
    assert str(info.value) == "the mesh has too few vertices (2 < 4)"


@pytest.mark.parametrize("offset", [[0.0, 0.0, -1e-69], [1e-69, 0.0, 0.0]])
def test_the_extent_is_the_largest_side_of_the_box_not_the_coordinates_spread(offset):
    # a tetrahedron of side 5e-71 beside the origin: the coordinates spread over 1e-69, its box does not
    with pytest.raises(InvalidMeshError, match="too small"):
        cleaning.validate(TETRA * 5e-71 + offset, TETRA_FACES)


def test_vertex_components_label_each_piece_and_a_vertex_in_no_face_alone():
    v = np.vstack([TETRA, TETRA + [5.0, 0.0, 0.0], [[9.0, 9.0, 9.0]], TETRA[:3] + [0.0, 7.0, 0.0]])
    f = np.vstack([TETRA_FACES, TETRA_FACES + 4, [[9, 10, 11]]])
    labels = cleaning.vertex_components(Mesh(v, f))
    assert labels.dtype == np.int64 and labels.shape == (12,)
    groups = {frozenset(np.flatnonzero(labels == k).tolist()) for k in np.unique(labels)}
    assert groups == {frozenset(range(4)), frozenset(range(4, 8)), frozenset([8]), frozenset([9, 10, 11])}


def test_vertex_components_label_a_last_vertex_in_no_face():
    v = np.vstack([TETRA, [[9.0, 9.0, 9.0]]])
    labels = cleaning.vertex_components(Mesh(v, TETRA_FACES))
    assert labels.shape == (5,) and len(set(labels[:4].tolist())) == 1 and labels[4] != labels[0]
