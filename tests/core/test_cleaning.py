"""Cleaning: welding and tolerances relative to the mesh's size, the components policy, the vertex limit."""

from __future__ import annotations

import io
import re

import numpy as np
import pytest
import trimesh

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
