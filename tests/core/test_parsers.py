"""Parser slips in OBJ, OFF, PLY and STL: each one found in the wild, each with its regression test."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import trimesh

from app.core.mesh import InvalidMeshError, load_mesh

TETRA_V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
TETRA_AREA = 1.5 + np.sqrt(3) / 2


def obj_lines(vertices=TETRA_V, faces=TETRA_F) -> list[str]:
    return [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]


def same_tetra(mesh) -> bool:
    return (
        mesh.n_vertices == 4
        and np.allclose(mesh.vertices, TETRA_V)
        and mesh.area() == pytest.approx(TETRA_AREA)
    )


def prism(sides: int) -> tuple[np.ndarray, list[list[int]]]:
    """A closed n-sided prism: two n-gon caps and n quads (unit circumradius, height 1)."""
    a = 2 * np.pi * np.arange(sides) / sides
    ring = np.column_stack([np.cos(a), np.sin(a), np.zeros(sides)])
    v = np.vstack([ring, ring + [0, 0, 1]])
    caps = [list(range(sides))[::-1], list(range(sides, 2 * sides))]
    sides_ = [[i, (i + 1) % sides, sides + (i + 1) % sides, sides + i] for i in range(sides)]
    return v, caps + sides_


def prism_area(sides: int) -> float:
    cap = 0.5 * sides * np.sin(2 * np.pi / sides)
    return 2 * cap + sides * 2 * np.sin(np.pi / sides)


# ---------------------------------------------------------------- OBJ


def test_obj_with_a_utf8_bom():
    data = b"\xef\xbb\xbf" + "\n".join(obj_lines()).encode()
    assert same_tetra(load_mesh(data, "obj"))


@pytest.mark.parametrize("newline", [b"\r", b"\r\n", b"\n"])
def test_obj_line_ends(newline):
    """CR-only (classic Mac) line ends used to read as one line and an empty mesh."""
    assert same_tetra(load_mesh(newline.join(s.encode() for s in obj_lines()), "obj"))


def test_obj_mixed_width_vertex_lines_keep_their_coordinates():
    """'v x y z' and 'v x y z r g b' mixed: the fast path used to reshape by the average width."""
    lines = obj_lines()
    lines[1] = "v 1 0 0 0.5 0.5 0.5"
    lines[3] = "v 0 0 1 1"
    mesh = load_mesh("\n".join(lines).encode(), "obj")
    assert same_tetra(mesh)


def test_obj_extra_columns_read_the_first_three():
    lines = [f"v {x} {y} {z} 0.1 0.2 0.3" for x, y, z in TETRA_V] + obj_lines()[4:]
    assert same_tetra(load_mesh("\n".join(lines).encode(), "obj"))


def test_obj_face_index_zero_is_refused():
    lines = obj_lines()[:4] + ["f 0 1 2", "f 1 2 3", "f 1 3 4", "f 2 3 4"]
    with pytest.raises(InvalidMeshError, match="refers to vertex 0, but OBJ counts vertices from 1"):
        load_mesh("\n".join(lines).encode(), "obj")


def test_obj_relative_indices_and_slashes():
    lines = obj_lines()[:4] + ["f -4/1/1 -2//1 -3", "f 1/1 2/2 4/4", "f -4 -1 -2", "f 2 3 4"]
    mesh = load_mesh("\n".join(lines).encode(), "obj")
    assert same_tetra(mesh)


def test_obj_polygons_are_fanned():
    v, polys = prism(7)
    text = [f"v {x} {y} {z}" for x, y, z in v] + ["f " + " ".join(str(i + 1) for i in p) for p in polys]
    mesh = load_mesh("\n".join(text).encode(), "obj")
    assert mesh.n_faces == 2 * 5 + 7 * 2 and mesh.area() == pytest.approx(prism_area(7))


def test_obj_comments_and_continuations():
    lines = obj_lines()
    lines[0] = "v 0 0 0 # the origin"
    lines[5] = "f 1 2 \\\n 4"
    assert same_tetra(load_mesh(b"# header\n" + "\n".join(lines).encode(), "obj"))


def test_obj_non_numbers_are_named():
    with pytest.raises(InvalidMeshError, match="an OBJ vertex line holds something that is not a number"):
        load_mesh(b"v 0 0 zero\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n", "obj")


# ---------------------------------------------------------------- OFF


def off_text(
    v: np.ndarray, polys: list[list[int]], n_vertices: int | None = None, n_faces: int | None = None
) -> bytes:
    lines = [
        "OFF",
        f"{len(v) if n_vertices is None else n_vertices} {len(polys) if n_faces is None else n_faces} 0",
    ]
    lines += [f"{x} {y} {z}" for x, y, z in v]
    lines += [f"{len(p)} " + " ".join(map(str, p)) for p in polys]
    return ("\n".join(lines) + "\n").encode()


def test_off_seven_sided_faces_are_triangulated():
    """A 7-sided cap used to leak a numpy message; OFF allows polygons: fanned, area exact."""
    v, polys = prism(7)
    mesh = load_mesh(off_text(v, polys), "off")
    assert mesh.n_faces == 2 * 5 + 7 * 2
    assert mesh.area() == pytest.approx(prism_area(7))


def test_off_truncated_is_refused_not_half_read():
    v, polys = prism(6)
    data = off_text(v, polys)
    cut = data[: data.index(b"\n4 ") + 1]  # every vertex and both caps, no quad
    with pytest.raises(
        InvalidMeshError, match="declares 12 vertices and 8 faces, but the file holds only 14"
    ):
        load_mesh(cut, "off")


def test_off_with_more_lines_than_declared_is_refused():
    v, polys = prism(6)
    with pytest.raises(InvalidMeshError, match="the counts are wrong"):
        load_mesh(off_text(v, polys, n_faces=5), "off")


def test_off_colours_comments_and_glued_header():
    v, polys = prism(5)
    lines = [f"OFF{len(v)} {len(polys)} 0  # some writers glue the counts to the keyword"]
    lines += [f"{x} {y} {z} 0.5 0.5 0.5 1" for x, y, z in v]
    lines += [f"{len(p)} " + " ".join(map(str, p)) + " 0.1 0.2 0.3" for p in polys]
    mesh = load_mesh("\n".join(lines).encode(), "off")
    assert mesh.area() == pytest.approx(prism_area(5))


def test_off_face_with_too_few_indices():
    data = b"OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n4 1 2 3\n"
    with pytest.raises(InvalidMeshError, match="fewer corners than its count says"):
        load_mesh(data, "off")


# ---------------------------------------------------------------- PLY


def ply_binary(v: np.ndarray, polys: list[list[int]], endian: str = "<", extra: bytes = b"") -> bytes:
    name = "binary_little_endian" if endian == "<" else "binary_big_endian"
    head = (
        f"ply\nformat {name} 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\n"
        f"property float z\nelement face {len(polys)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    body = np.asarray(v, endian + "f4").tobytes()
    body += b"".join(struct.pack(f"{endian}B{len(p)}i", len(p), *p) for p in polys)
    return head + body + extra


@pytest.mark.parametrize("endian", ["<", ">"])
def test_binary_ply_mixing_triangles_and_quads(endian):
    v, polys = prism(3)  # two triangles, three quads
    mesh = load_mesh(ply_binary(v, polys, endian), "ply")
    assert mesh.n_faces == 2 + 3 * 2 and mesh.area() == pytest.approx(prism_area(3), rel=1e-6)


def test_binary_ply_all_triangles_reads_like_trimesh_writes_it():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    mesh = load_mesh(sphere.export(file_type="ply"), "ply")
    assert np.allclose(mesh.vertices, sphere.vertices) and np.array_equal(mesh.faces, sphere.faces)


def test_ascii_ply_mixing_triangles_and_quads():
    v, polys = prism(4)
    head = (
        f"ply\nformat ascii 1.0\nelement vertex {len(v)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {len(polys)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    body = [f"{x} {y} {z}" for x, y, z in v] + [f"{len(p)} " + " ".join(map(str, p)) for p in polys]
    mesh = load_mesh((head + "\n".join(body) + "\n").encode(), "ply")
    assert mesh.area() == pytest.approx(prism_area(4))


def test_binary_ply_truncated_is_refused():
    v, polys = prism(6)
    data = ply_binary(v, polys)
    with pytest.raises(InvalidMeshError, match="truncated"):
        load_mesh(data[:-10], "ply")


def test_binary_ply_with_more_data_than_declared_is_refused():
    v, polys = prism(6)
    with pytest.raises(InvalidMeshError, match="bytes more than its header declares"):
        load_mesh(ply_binary(v, polys, extra=bytes(200)), "ply")


# ---------------------------------------------------------------- STL


def test_binary_stl_whose_count_lies_says_so():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    data = bytearray(sphere.export(file_type="stl"))
    data[80:84] = struct.pack("<I", 5000)
    with pytest.raises(InvalidMeshError) as err:
        load_mesh(bytes(data), "stl")
    assert "declares 5000 triangles (250084 bytes), but the file holds 16084 bytes" in str(err.value)
    assert "no vertices" not in str(err.value)


def test_ascii_stl_cut_between_facets_is_refused():
    text = trimesh.exchange.stl.export_stl_ascii(trimesh.creation.icosphere(subdivisions=1))
    cut = text[: text.index("endfacet", len(text) // 2) + len("endfacet")]
    with pytest.raises(InvalidMeshError, match="does not end with 'endsolid': it is truncated"):
        load_mesh(cut.encode(), "stl")


def test_ascii_and_binary_stl_agree():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    binary = load_mesh(sphere.export(file_type="stl"), "stl")
    ascii_ = load_mesh(trimesh.exchange.stl.export_stl_ascii(sphere).encode(), "stl")
    assert np.array_equal(binary.faces, ascii_.faces)
    assert np.allclose(binary.vertices, ascii_.vertices, atol=1e-6)
