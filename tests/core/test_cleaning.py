"""Cleaning: welding and tolerances relative to the mesh's size, the components policy, the vertex limit."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest
import trimesh

from app.core import cleaning
from app.core.cleaning import _groups, face_components, merge_vertices, unique_face_index
from app.core.mesh import InvalidMeshError, Mesh, clean, load_mesh, validate
from app.core.pipeline import DescribeParams, describe
from app.datasets import locate
from tests.conftest import needs_dataset

REALWORLD = locate.dataset_dir("realworld")
needs_realworld = needs_dataset("realworld")


def obj_text(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """Full float64 precision ('%.17g'): the file holds exactly the array."""
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    return ("\n".join(lines) + "\n").encode()


def components(mesh: Mesh) -> int:
    return int(face_components(mesh.faces, mesh.n_vertices).max()) + 1


@pytest.fixture(scope="module")
def sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=3)


@pytest.mark.parametrize("scale", [1e-9, 1e-3, 1.0, 1e6, 1e12])
@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_loading_is_scale_and_translation_invariant(sphere, scale, offset):
    """Same topology and the same shape (up to the similarity) from 1e-9 to 1e12, far from the origin too."""
    size = 2.0  # the unit sphere's diameter
    reference = load_mesh(obj_text(sphere.vertices, sphere.faces), "obj")
    moved = sphere.vertices * scale + offset * size * scale
    mesh = load_mesh(obj_text(moved, sphere.faces), "obj")
    assert np.array_equal(mesh.faces, reference.faces)
    back = (mesh.vertices - offset * size * scale) / scale
    assert np.allclose(back, reference.vertices, atol=1e-9 * (1 + offset))
    assert mesh.area() == pytest.approx(reference.area() * scale**2, rel=1e-6)


@pytest.mark.parametrize("scale", [1e-9, 1e12])
def test_stl_corners_weld_at_any_scale(sphere, scale):
    """Binary STL repeats each corner per triangle (float32): welding joins them at 1e-9 and 1e12 alike."""
    scaled = trimesh.Trimesh(sphere.vertices * scale, sphere.faces, process=False)
    mesh = load_mesh(scaled.export(file_type="stl"), "stl")
    assert mesh.n_vertices == len(sphere.vertices) and mesh.n_faces == len(sphere.faces)


def test_description_is_scale_invariant(sphere):
    """The whole path (load, clean, resample, describe) gives the same HKS at 1e-9, 1 and 1e12."""
    ellipsoid = sphere.vertices * [0.6, 0.8, 2.0]
    params = DescribeParams(k=40, m=16, target_vertices=642)
    hks = [
        describe(load_mesh(obj_text(ellipsoid * s + 3e6 * s, sphere.faces), "obj"), params).hks
        for s in (1e-9, 1.0, 1e12)
    ]
    assert np.allclose(hks[0], hks[1], atol=1e-4) and np.allclose(hks[2], hks[1], atol=1e-4)


def test_seams_weld_on_position_alone():
    """An export that splits vertices along UV/normal seams (here: every face its own corners, each with
    its own normal and UV) welds back to the closed surface."""
    box = trimesh.creation.box()
    corners = box.vertices[box.faces].reshape(-1, 3)
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in corners]
    lines += [f"vt {i % 2} {i % 3}" for i in range(len(corners))]
    lines += [f"vn {x:g} {y:g} {z:g}" for x, y, z in np.repeat(box.face_normals, 3, axis=0)]
    corner = [f"{k}/{k}/{k}" for k in range(1, len(corners) + 1)]  # v/vt/vn, each its own
    lines += ["f " + " ".join(corner[3 * i : 3 * i + 3]) for i in range(len(box.faces))]
    mesh = load_mesh("\n".join(lines).encode(), "obj")
    assert mesh.n_vertices == 8 and mesh.n_faces == 12
    assert components(mesh) == 1


def test_degenerate_threshold_is_relative(sphere):
    """A sliver is dropped at any scale; a small but real face is kept at any scale."""
    for scale in (1e-9, 1.0, 1e12):
        v = np.vstack([sphere.vertices, sphere.vertices[:2].mean(axis=0, keepdims=True)]) * scale
        f = np.vstack([sphere.faces, [[0, 1, len(sphere.vertices)]]])  # collinear: zero area
        out = clean(validate(v, f))
        assert out.n_faces == len(sphere.faces)


def hundred_parts(subdivisions: int = 1) -> trimesh.Trimesh:
    part = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.4)
    grid = np.stack(np.meshgrid(np.arange(10), np.arange(10), [0]), axis=-1).reshape(-1, 3)
    return trimesh.util.concatenate([part.copy().apply_translation(p) for p in grid])


def test_a_shape_of_a_hundred_equal_parts_is_kept_whole():
    plate = hundred_parts()
    mesh = clean(Mesh(np.asarray(plate.vertices), np.asarray(plate.faces)))
    assert mesh.n_vertices == len(plate.vertices) and components(mesh) == 100


def test_debris_is_small_relative_to_the_largest_part():
    """Crumbs under 1 % of the largest part's area go, even among 100 parts; parts at 2 % stay."""
    plate = hundred_parts()
    part_area = plate.area / 100
    crumb = trimesh.creation.icosphere(subdivisions=1, radius=0.4 * np.sqrt(0.005)).apply_translation(
        [20, 0, 0]
    )
    pebble = trimesh.creation.icosphere(subdivisions=1, radius=0.4 * np.sqrt(0.02)).apply_translation(
        [-20, 0, 0]
    )
    assert crumb.area < 0.01 * part_area < pebble.area
    tm = trimesh.util.concatenate([plate, crumb, pebble])
    mesh = clean(Mesh(np.asarray(tm.vertices), np.asarray(tm.faces)))
    assert components(mesh) == 101
    assert mesh.area() == pytest.approx(plate.area + pebble.area, rel=1e-12)


def test_an_instanced_hundred_part_glb_is_described():
    """One mesh placed by 100 nodes (how GLB instances parts): loaded whole and described (100 zero
    eigenvalues, one per part, then the spectrum that carries the shape)."""
    part = trimesh.creation.icosphere(subdivisions=0, radius=0.4)
    scene = trimesh.Scene()
    for i in range(100):
        at = trimesh.transformations.translation_matrix([i % 10, i // 10, 0])
        scene.add_geometry(part, geom_name="part", node_name=f"n{i}", transform=at)
    mesh = load_mesh(scene.export(file_type="glb"), "glb")
    assert mesh.n_vertices == 100 * len(part.vertices) and components(mesh) == 100
    description = describe(mesh, DescribeParams(k=120, m=16, target_vertices=mesh.n_vertices))
    assert np.isfinite(description.hks).all() and description.n_vertices == mesh.n_vertices
    assert np.sum(description.eigenvalues < 1e-8 * description.eigenvalues.max()) == 100


def test_a_triangle_soup_is_refused_with_the_reason():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(300, 3))
    with pytest.raises(InvalidMeshError, match="triangle soup: its 100 faces form 100 separate pieces"):
        clean(validate(v, np.arange(300).reshape(-1, 3)))


@pytest.mark.parametrize(
    ("coordinate", "message"), [(1e300, "coordinates are too large"), (1e-200, "too small")]
)
def test_extreme_coordinates_say_so(sphere, coordinate, message):
    data = obj_text(sphere.vertices * coordinate, sphere.faces)
    with pytest.raises(InvalidMeshError, match=message):
        load_mesh(data, "obj")


def test_near_double_overflow_is_not_called_zero_area():
    text = obj_text(trimesh.creation.box().vertices * 1e308, trimesh.creation.box().faces)
    with pytest.raises(InvalidMeshError, match="coordinates are too large") as err:
        load_mesh(text, "obj")
    assert "zero total area" not in str(err.value)


def test_vertex_limit_counts_welded_vertices(sphere):
    """A binary STL of a 642-vertex sphere holds 3840 corners: within a limit of 700, refused at 600."""
    data = sphere.export(file_type="stl")
    assert load_mesh(data, "stl", max_vertices=700).n_vertices == 642
    with pytest.raises(
        InvalidMeshError, match="642 vertices once duplicates are welded, more than the limit of 600"
    ):
        load_mesh(data, "stl", max_vertices=600)


@needs_realworld
def test_realworld_soup_is_refused_as_a_soup():
    """trimesh__soup.stl: 100 triangles, none sharing a vertex; no surface to describe."""
    with pytest.raises(InvalidMeshError, match="triangle soup"):
        load_mesh(REALWORLD / "trimesh__soup.stl")


@needs_realworld
@pytest.mark.parametrize(
    ("name", "parts"),
    [
        ("thingi10k__multiple_components__42841.stl", 2),
        ("thingi10k__multiple_components__61458.stl", 4),
        ("thingi10k__multiple_components__71987.stl", 2),
        ("thingi10k__fragmented__63451.stl", 30),
        ("thingi10k__fragmented__65583.stl", 15),
        ("thingi10k__fragmented__65778.stl", 10),
        ("trimesh__pyramids.3mf", 12),
    ],
)
def test_realworld_parts_are_all_kept(name, parts):
    """Each part of these multi-part prints is a real part: the count matches STATS.csv's components."""
    mesh = load_mesh(REALWORLD / name)
    assert components(mesh) == parts
    raw = trimesh.load(
        io.BytesIO((REALWORLD / name).read_bytes()), file_type=name.rsplit(".", 1)[1].lower(), force="mesh"
    )
    assert mesh.area() == pytest.approx(raw.area, rel=1e-6)  # nothing dropped but degenerate slivers


def test_messages_are_sentences_not_internals():
    with pytest.raises(InvalidMeshError) as err:
        clean(validate(np.random.default_rng(1).normal(size=(9, 3)), np.arange(9).reshape(-1, 3)))
    assert not re.search(r"Error|numpy|index \d+ is out of bounds|Traceback", str(err.value))


def test_row_grouping_matches_numpy_unique():
    """The exact fallback of the welding hash (and of face dedup past 2^21 vertices) against np.unique."""
    keys = np.random.default_rng(3).integers(0, 4, size=(2000, 3))
    first, inverse = _groups(keys)
    expected, expected_first = np.unique(keys, axis=0, return_index=True)
    assert np.array_equal(keys[first][inverse], keys)  # every row maps to a row equal to it
    assert np.array_equal(np.sort(first), np.sort(expected_first)) and len(first) == len(expected)


def test_welding_keeps_input_order_and_every_face():
    rng = np.random.default_rng(4)
    v = rng.random((60, 3))
    v = np.vstack([v, v[::-1]])  # each position twice
    faces = rng.integers(0, 120, size=(300, 3))
    welded, f = merge_vertices(v, faces)
    assert np.array_equal(welded[f], v[faces])  # every corner where it was
    assert len(welded) == len(np.unique(v[np.unique(faces)], axis=0))
    first_seen = [np.flatnonzero((v == w).all(axis=1) & np.isin(np.arange(120), faces)).min() for w in welded]
    assert first_seen == sorted(first_seen)


def test_face_dedup_is_the_same_for_small_and_large_vertex_counts():
    faces = np.random.default_rng(5).integers(0, 30, size=(500, 3))
    faces = np.vstack([faces, faces[:, ::-1]])  # every face again, reversed
    small, large = unique_face_index(faces, 30), unique_face_index(faces, 2**22)
    assert np.array_equal(small, large) and np.all(small < 500)


# Validation and cleaning at their thresholds: tolerances relative to the
# mesh's size, hit exactly or on either side.


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


def test_an_empty_mesh_is_a_clear_refusal():
    """What a resampling that kept nothing hands on: an InvalidMeshError (422, never retried), not a
    numpy reduction error."""
    with pytest.raises(InvalidMeshError, match="no faces left"):
        clean(Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64)))
