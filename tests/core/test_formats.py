"""Readers: every format loads a real file of its kind; unsupported formats say what to convert to."""

from __future__ import annotations

import base64
import io
import json
import re
import struct
import sys
import zipfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from app.core.cleaning import face_components
from app.core.formats import containers, scene
from app.core.formats.common import (
    BOM,
    fan_triangulate,
    first_columns,
    indices,
    numbers,
    text_lines,
    whole_numbers,
)
from app.core.formats.dae import read_dae
from app.core.formats.gltf import (
    MAX_INSTANCES,
    _buffers,
    _canonical_glb,
    _check_counts,
    _check_extensions,
    _check_views,
    _instances,
    _split_glb,
    read_glb,
    read_gltf,
    read_zip,
)
from app.core.formats.obj import read_obj
from app.core.formats.off import read_off
from app.core.formats.other import read_drc
from app.core.formats.ply import read_ply
from app.core.formats.scene import load_with_trimesh, scene_arrays, short
from app.core.formats.stl import read_stl
from app.core.formats.threemf import read_3mf
from app.core.mesh import (
    SUPPORTED_FORMATS,
    InvalidMeshError,
    UnsupportedFormatError,
    detect_format,
    load_mesh,
)
from app.core.meshdata import FACE_FACTOR, RAW_VERTEX_FACTOR, Budget
from app.datasets import locate
from tests.conftest import needs_dataset

REALWORLD = locate.dataset_dir("realworld")
needs_realworld = needs_dataset("realworld")
# what a user must never read: exception class names, numpy internals, Python object reprs
INTERNALS = re.compile(
    r"Error\b|Exception|numpy|ndarray|NoneType|object is not|subscriptable|Traceback|\bint\("
)


def readable(message: str) -> bool:
    return not INTERNALS.search(message)


def glb(doc: dict, blob: bytes = b"") -> bytes:
    """A GLB from a glTF JSON document and its binary chunk."""
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text
    if blob:
        body += struct.pack("<II", len(blob), 0x004E4942) + blob
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def tetra_doc(nodes: list[dict], **extra) -> tuple[dict, bytes]:
    """A glTF tetrahedron (4 float32 positions, 12 uint16 indices) placed by `nodes`."""
    blob = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "<f4").tobytes()
    blob += np.array([0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3], "<u2").tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 24},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"},
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": nodes,
        "scenes": [
            {"nodes": [i for i, n in enumerate(nodes) if not any(i in m.get("children", []) for m in nodes)]}
        ],
        "scene": 0,
        **extra,
    }
    return doc, blob


def zip_folder(folder: Path, inside: str = "") -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as archive:
        for path in sorted(folder.iterdir()):
            archive.write(path, inside + path.name)
    return buf.getvalue()


def n_components(mesh) -> int:
    return int(face_components(mesh.faces, mesh.n_vertices).max()) + 1


# ---------------------------------------------------------------- detection and unsupported formats


def test_detect_format_knows_the_new_formats():
    assert detect_format("Print.3MF") == "3mf" and detect_format("tree.gltf.glb") == "glb"
    assert {"gltf", "zip", "3mf", "dae", "drc"} <= set(SUPPORTED_FORMATS)


@pytest.mark.parametrize(
    ("name", "says"),
    [
        ("glass.wrl", "VRML (.wrl) is not supported: export it as OBJ, PLY, STL, GLB or 3MF"),
        ("head.ctm", "OpenCTM (.ctm) is not supported: export it as"),
        ("angel.vtp", "VTK (.vtp) is not supported: export it as"),
        ("scan.xyz", "(.xyz) is a point cloud, and shapebag needs a surface"),
        ("car.fbx", "FBX (.fbx) is not supported"),
        ("thing.qqq", "unsupported mesh format 'qqq': use one of .obj"),
    ],
)
def test_unsupported_formats_name_themselves_and_what_to_do(name, says):
    with pytest.raises(UnsupportedFormatError) as err:
        load_mesh(b"anything", name)
    assert says in str(err.value) and "unsupported mesh format" in str(err.value)
    assert isinstance(err.value, InvalidMeshError)  # callers that catch InvalidMeshError still do


@needs_realworld
@pytest.mark.parametrize(
    "name",
    ["trimesh__headless.ctm", "vtk__WineGlass.wrl", "vtk__owl_decimated.vtp", "trimesh__points_agisoft.xyz"],
)
def test_realworld_unsupported_files_are_refused_by_format(name):
    with pytest.raises(UnsupportedFormatError, match=r"\(\.(ctm|wrl|vtp|xyz)\)"):
        load_mesh(REALWORLD / name)


def test_meshopt_glb_is_unsupported_with_advice():
    doc, blob = tetra_doc([{"mesh": 0}], extensionsUsed=["EXT_meshopt_compression"])
    doc["extensionsRequired"] = ["EXT_meshopt_compression"]
    with pytest.raises(UnsupportedFormatError, match="meshopt-compressed glTF .* export it without meshopt"):
        load_mesh(glb(doc, blob), "glb")


# ---------------------------------------------------------------- glTF / GLB


def test_glb_node_transforms_are_baked():
    """Two nodes place one tetrahedron: one moved by (10, 0, 0), one scaled by 2 and turned 90° about z."""
    quarter = [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]  # x, y, z, w
    doc, blob = tetra_doc(
        [{"mesh": 0, "translation": [10, 0, 0]}, {"mesh": 0, "scale": [2, 2, 2], "rotation": quarter}]
    )
    mesh = load_mesh(glb(doc, blob), "glb")
    tetra = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    rotated = 2 * tetra @ np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1]], float)  # (x, y, z) -> (-y, x, z), x2
    expected = np.vstack([tetra + [10, 0, 0], rotated])
    got = np.unique(np.round(mesh.vertices, 6), axis=0)
    assert np.allclose(got, np.unique(np.round(expected, 6), axis=0))
    assert n_components(mesh) == 2


def test_glb_child_nodes_compose_their_parents_transforms():
    doc, blob = tetra_doc([{"children": [1], "translation": [0, 5, 0]}, {"mesh": 0, "scale": [3, 3, 3]}])
    mesh = load_mesh(glb(doc, blob), "glb")
    assert np.allclose(mesh.vertices.min(axis=0), [0, 5, 0]) and np.allclose(
        mesh.vertices.max(axis=0), [3, 8, 3]
    )


def test_glb_seams_are_welded():
    """A GLB whose vertices are split per face (flat shading, UV seams) welds back to 8 box corners."""
    box = trimesh.creation.box()
    split = trimesh.Trimesh(
        box.vertices[box.faces].reshape(-1, 3), np.arange(36).reshape(-1, 3), process=False
    )
    mesh = load_mesh(split.export(file_type="glb"), "glb")
    assert mesh.n_vertices == 8 and mesh.n_faces == 12


def test_glb_with_an_external_buffer_names_the_file():
    doc, _ = tetra_doc([{"mesh": 0}])
    doc["buffers"] = [{"byteLength": 72, "uri": "x.bin"}]
    with pytest.raises(InvalidMeshError) as err:
        load_mesh(glb(doc), "glb")
    message = str(err.value)
    assert "the GLB refers to an external file 'x.bin'; upload a .zip holding both" in message
    assert readable(message)


def test_self_contained_gltf_with_data_uris():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    data = sphere.export(file_type="gltf", embed_buffers=True)["model.gltf"]
    mesh = load_mesh(data, "gltf")
    assert mesh.n_vertices == len(sphere.vertices) and mesh.area() == pytest.approx(sphere.area, rel=1e-6)


def test_gltf_in_a_zip_with_its_bin():
    doc, blob = tetra_doc([{"mesh": 0}])
    doc["buffers"] = [{"byteLength": len(blob), "uri": "data/tetra%20mesh.bin"}]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as archive:
        archive.writestr("model/scene.gltf", json.dumps(doc))
        archive.writestr("model/data/tetra mesh.bin", blob)
        archive.writestr("model/texture.png", b"not even a png")  # textures are ignored
    mesh = load_mesh(buf.getvalue(), "upload.zip")
    assert mesh.n_vertices == 4 and mesh.area() == pytest.approx(1.5 + np.sqrt(3) / 2)


@pytest.mark.parametrize(
    ("members", "says"),
    [
        ({"a.txt": b"hello"}, "holds no .gltf or .glb"),
        ({"a.gltf": b"{}", "b.glb": b"glTF"}, "several models"),
        (
            {
                "a.gltf": json.dumps(
                    tetra_doc([{"mesh": 0}])[0] | {"buffers": [{"byteLength": 72, "uri": "gone.bin"}]}
                )
            },
            "refers to 'gone.bin', which is not in the .zip",
        ),
    ],
)
def test_zip_problems_are_named(members, says):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)
    with pytest.raises(InvalidMeshError, match=re.escape(says)):
        load_mesh(buf.getvalue(), "zip")


def test_zip_bomb_is_refused_before_unpacking():
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("model.gltf", b" " * (200 << 20))  # 200 MB of spaces, ~200 KB packed
    with pytest.raises(InvalidMeshError, match="unpacks to 209715200 bytes, more than"):
        load_mesh(buf.getvalue(), "zip", max_vertices=100_000)


@needs_realworld
@pytest.mark.parametrize(
    ("folder", "vertices", "parts"), [("gltf_fox", 290, 1), ("gltf_trimesh_TestScene", 585, 9)]
)
def test_realworld_gltf_folders_load_as_a_zip(tmp_path, folder, vertices, parts):
    """Vertex counts after welding as STATS.csv reports them (merged_verts)."""
    data = zip_folder(REALWORLD / folder, inside=f"{folder}/")
    (tmp_path / "upload.zip").write_bytes(data)
    mesh = load_mesh(tmp_path / "upload.zip")
    assert mesh.n_vertices == vertices
    assert n_components(mesh) <= parts


@needs_realworld
def test_realworld_gltf_alone_says_which_file_is_missing():
    with pytest.raises(InvalidMeshError, match="external file 'Fox.bin'; upload a .zip"):
        load_mesh(REALWORLD / "gltf_fox" / "Fox.gltf")


# ---------------------------------------------------------------- Draco


def test_draco_glb_decodes_to_its_plain_version():
    """The same sphere, plain and Draco-compressed (14-bit quantisation): same topology, positions within
    the quantisation step."""
    sphere = trimesh.creation.icosphere(subdivisions=3)
    plain = load_mesh(trimesh.Scene(sphere).export(file_type="glb"), "glb")
    draco_bytes = trimesh.exchange.gltf.export_glb(trimesh.Scene(sphere), extension_draco=True)
    assert b"KHR_draco_mesh_compression" in draco_bytes
    draco = load_mesh(draco_bytes, "glb")
    assert draco.n_vertices == plain.n_vertices and draco.n_faces == plain.n_faces
    assert draco.area() == pytest.approx(plain.area(), rel=1e-3)
    order = np.lexsort(np.round(plain.vertices, 2).T)
    dorder = np.lexsort(np.round(draco.vertices, 2).T)
    assert np.abs(draco.vertices[dorder] - plain.vertices[order]).max() < 2 * 2.0 / 2**14


def test_raw_draco_bitstream():
    import DracoPy

    sphere = trimesh.creation.icosphere(subdivisions=2)
    data = DracoPy.encode(np.asarray(sphere.vertices, np.float32), np.asarray(sphere.faces, np.uint32))
    mesh = load_mesh(data, "mesh.drc")
    assert mesh.n_vertices == len(sphere.vertices)
    assert mesh.area() == pytest.approx(sphere.area, rel=1e-3)


@needs_realworld
def test_realworld_draco_box_is_the_unit_cube():
    mesh = load_mesh(REALWORLD / "draco__Box_Draco.glb")
    assert mesh.n_vertices == 8 and mesh.n_faces == 12
    assert mesh.area() == pytest.approx(6.0, rel=1e-3)
    assert np.allclose(mesh.vertices.min(axis=0), -0.5, atol=1e-3) and np.allclose(
        mesh.vertices.max(axis=0), 0.5, atol=1e-3
    )


@needs_realworld
@pytest.mark.parametrize(
    ("name", "vertices", "height"),
    [("draco__CesiumMan.glb", 2338, 1.5), ("draco__SheenCloth.glb", 58081, None)],
)
def test_realworld_draco_glbs_decode_to_plausible_meshes(name, vertices, height):
    """CesiumMan: a 1.5 m tall closed body (STATS: 2338 welded vertices, watertight)."""
    mesh = load_mesh(REALWORLD / name)
    assert mesh.n_vertices == vertices and n_components(mesh) == 1
    extent = np.ptp(mesh.vertices, axis=0)
    if height is not None:
        assert extent.max() == pytest.approx(height, rel=0.05)
    assert mesh.area() > 0.01 * extent.max() ** 2  # not collapsed, not garbage


@needs_realworld
def test_realworld_raw_draco_car():
    mesh = load_mesh(REALWORLD / "draco__car.drc")
    assert mesh.n_vertices > 500 and mesh.n_faces > 1000
    assert mesh.area() > 0.01 * np.ptp(mesh.vertices, axis=0).max() ** 2


# ---------------------------------------------------------------- 3MF, COLLADA


@needs_realworld
@pytest.mark.parametrize(
    ("name", "vertices", "parts"),
    [
        ("trimesh__cube_and_sphere_same_name.3mf", 2570, 2),
        ("trimesh__pyramids.3mf", 1662, 12),
        ("trimesh__counterXP.3MF", None, None),
        ("trimesh__P_XPM_0331_01.3mf", 4, 1),
    ],
)
def test_realworld_3mf(name, vertices, parts):
    mesh = load_mesh(REALWORLD / name)
    if vertices is not None:
        assert mesh.n_vertices == vertices and n_components(mesh) == parts
    assert mesh.area() > 0


def test_3mf_round_trip_keeps_the_shape():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    mesh = load_mesh(sphere.export(file_type="3mf"), "3mf")
    assert mesh.n_vertices == len(sphere.vertices) and mesh.area() == pytest.approx(sphere.area, rel=1e-5)


@needs_realworld
def test_realworld_collada_cube():
    """blue_cube.dae: a 2 x 2 x 2 cube (24 split vertices welded to 8), area 24."""
    mesh = load_mesh(REALWORLD / "trimesh__blue_cube.dae")
    assert mesh.n_vertices == 8 and mesh.n_faces == 12
    assert mesh.area() == pytest.approx(24.0, rel=1e-5)
    assert np.allclose(np.ptp(mesh.vertices, axis=0), 2.0, atol=1e-5)


# ---------------------------------------------------------------- declared counts: refused before allocating


def _glb_accessor_bomb() -> bytes:
    doc, blob = tetra_doc([{"mesh": 0}])
    doc["bufferViews"][0]["byteLength"] = 4_000_000_000
    doc["accessors"][0]["count"] = 1_000_000_000
    return glb(doc, blob)


def _glb_instancing_bomb(levels: int = 40) -> bytes:
    """Each node lists the next one twice as a child: 2^40 placements of one tetrahedron."""
    nodes = [{"children": [i + 1, i + 1]} for i in range(levels)] + [{"mesh": 0}]
    doc, blob = tetra_doc(nodes)
    doc["scenes"] = [{"nodes": [0]}]
    return glb(doc, blob)


BOMBS = {
    "stl-count": (
        "stl",
        b"\0" * 80 + struct.pack("<I", 4_000_000_000) + b"\0" * 50,
        "declares 4000000000 triangles",
    ),
    "ply-header": (
        "ply",
        b"ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\n"
        b"property float x\nproperty float y\nproperty float z\nelement face 2000000000\n"
        b"property list uchar int vertex_indices\nend_header\n" + bytes(64),
        "declares 2000000000 vertices",
    ),
    "off-header": ("off", b"OFF\n1000000000 2000000000 0\n0 0 0\n", "declares 1000000000 vertices"),
    "glb-accessor": ("glb", _glb_accessor_bomb(), "runs past the end of its buffer"),
    "glb-instances": ("glb", _glb_instancing_bomb(), "places .* meshes, more than the limit"),
}


@pytest.mark.parametrize("case", sorted(BOMBS))
def test_absurd_declared_counts_are_refused_without_allocating(case):
    import tracemalloc

    fmt, data, says = BOMBS[case]
    tracemalloc.start()
    try:
        with pytest.raises(InvalidMeshError, match=says) as err:
            load_mesh(data, fmt, max_vertices=2_000_000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 << 20  # bytes: nothing near the declared size was allocated
    assert readable(str(err.value))


def test_declared_counts_within_reason_but_over_the_limit_are_refused_early():
    sphere = trimesh.creation.icosphere(subdivisions=4)  # 2562 vertices, 5120 triangles
    with pytest.raises(
        InvalidMeshError, match="declares 5120 faces: far more than a mesh within the limit of 100"
    ):
        load_mesh(sphere.export(file_type="stl"), "stl", max_vertices=100)


def test_datauri_glb_round_trip():
    """A GLB whose only buffer is a data: URI (no binary chunk) reads the same as a plain one."""
    doc, blob = tetra_doc([{"mesh": 0}])
    doc["buffers"] = [
        {
            "byteLength": len(blob),
            "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode(),
        }
    ]
    assert load_mesh(glb(doc), "glb").n_faces == 4


@pytest.mark.parametrize(("fmt", "where"), [("3mf", "the 3MF build"), ("glb", "the glTF scene")])
def test_placements_of_one_part_count_against_the_limit_before_they_are_copied(fmt, where):
    """50 placements of one 42-vertex part: 2100 vertices, within 6 x 400 raw, over 6 x 300."""
    part = trimesh.creation.icosphere(subdivisions=1)
    scene = trimesh.Scene()
    for i in range(50):
        at = trimesh.transformations.translation_matrix([3 * i, 0, 0])
        scene.add_geometry(part, geom_name="part", node_name=f"n{i}", transform=at)
    data = scene.export(file_type=fmt)
    assert len(data) < 20_000  # the part is stored once
    assert n_components(load_mesh(data, fmt, max_vertices=2100)) == 50
    with pytest.raises(InvalidMeshError, match=f"{where} .* declares 2100 vertices"):
        load_mesh(data, fmt, max_vertices=300)


def _valid_files() -> dict[str, bytes]:
    import DracoPy

    sphere = trimesh.creation.icosphere(subdivisions=1)
    files = {fmt: sphere.export(file_type=fmt) for fmt in ("obj", "off", "ply", "stl", "glb", "3mf")}
    files["gltf"] = sphere.export(file_type="gltf", embed_buffers=True)["model.gltf"]
    files["drc"] = DracoPy.encode(
        np.asarray(sphere.vertices, np.float32), np.asarray(sphere.faces, np.uint32)
    )
    files["glb draco"] = trimesh.exchange.gltf.export_glb(trimesh.Scene(sphere), extension_draco=True)
    files["ply ascii"] = sphere.export(file_type="ply", encoding="ascii")
    files["stl ascii"] = trimesh.exchange.stl.export_stl_ascii(sphere)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("m.gltf", files["gltf"])
    files["zip"] = buf.getvalue()
    return {k: v if isinstance(v, bytes) else v.encode() for k, v in files.items()}


@pytest.mark.parametrize("kind", sorted(_valid_files()))
def test_damaged_files_are_refused_in_words(kind):
    """Truncations and random byte flips of a valid file: each either loads or raises InvalidMeshError
    with a readable sentence; never another exception, never a library's internals."""
    data = _valid_files()[kind]
    rng = np.random.default_rng(sum(map(ord, kind)))
    damaged = [data[: int(len(data) * k)] for k in np.linspace(0.05, 0.95, 10)]
    for _ in range(30):
        flipped = np.frombuffer(data, np.uint8).copy()
        flipped[rng.integers(0, len(data), size=4)] = rng.integers(0, 256, size=4)
        damaged.append(flipped.tobytes())
    unreadable = []
    for blob in damaged:
        try:
            load_mesh(blob, kind.split()[0], max_vertices=10_000)
        except InvalidMeshError as exc:
            if not readable(str(exc)) or len(str(exc)) > 300:
                unreadable.append(str(exc))
    assert not unreadable, unreadable


# The mesh readers' edges: zip containers' limits and refusals in words.


def _zip(members: dict[str, bytes], compression: int = zipfile.ZIP_STORED) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return buf.getvalue()


def _with_flag(data: bytes, bit: int) -> bytes:
    """The archive with a general-purpose flag bit set on its (one) central-directory entry."""
    at = data.index(b"PK\x01\x02") + 8
    raw = bytearray(data)
    raw[at] |= bit
    return bytes(raw)


def _refusal(fn, *args) -> str:
    with pytest.raises(InvalidMeshError) as info:
        fn(*args)
    return str(info.value)


def test_not_a_zip_is_refused_in_words():
    message = _refusal(
        containers.open_zip, b"solid cube\n", SimpleNamespace(unpacked_bytes=lambda: 100), "3MF"
    )
    assert message == "could not read the file as 3MF: it is not a valid zip archive"


def test_members_up_to_the_maximum_pass(monkeypatch):
    monkeypatch.setattr(containers, "MAX_MEMBERS", 3)
    budget = SimpleNamespace(unpacked_bytes=lambda: 1000)
    assert len(containers.open_zip(_zip({f"{i}.obj": b"" for i in range(3)}), budget, "zip").infolist()) == 3
    message = _refusal(containers.open_zip, _zip({f"{i}.obj": b"" for i in range(4)}), budget, "zip")
    assert message == "the zip archive holds 4 files, more than 3"


def test_an_archive_unpacking_to_exactly_the_budget_passes():
    budget = SimpleNamespace(unpacked_bytes=lambda: 10)
    containers.open_zip(_zip({"a.obj": b"x" * 10}), budget, "zip")
    message = _refusal(containers.open_zip, _zip({"a.obj": b"x" * 11}), budget, "zip")
    assert message == "the zip archive unpacks to 11 bytes, more than the 10 allowed"


def test_only_the_encryption_flag_refuses_an_archive():
    budget = SimpleNamespace(unpacked_bytes=lambda: 1000)
    plain = _zip({"a.obj": b"v 0 0 0\n"})
    containers.open_zip(_with_flag(plain, 0x2), budget, "zip")  # a compression option: fine
    message = _refusal(containers.open_zip, _with_flag(plain, 0x1), budget, "zip")
    assert message == "the zip archive is encrypted: upload it without a password"


def _corrupt(name: str) -> zipfile.ZipFile:
    data = bytearray(_zip({name: b"v 0 0 0\n" * 200}, zipfile.ZIP_DEFLATED))
    start = data.index(b"PK\x03\x04") + 30 + len(name.encode())
    data[start : start + 8] = b"\xff" * 8  # the deflate stream's first bytes
    return zipfile.ZipFile(io.BytesIO(bytes(data)))


def test_a_member_that_does_not_unpack_is_named_up_to_80_characters():
    name = "m" * 90 + ".obj"
    message = _refusal(containers.read_member, _corrupt(name), name, "zip")
    assert message == f"could not unpack '{'m' * 80}' from the zip archive: it is corrupt"


def test_a_damaged_archive_is_called_corrupt_in_words():
    message = _refusal(containers.check_members, _corrupt("a.obj"), "3MF")
    assert message == "the 3MF archive is corrupt: a file inside it does not unpack"


def test_an_unknown_extension_is_named_up_to_20_characters_with_the_supported_ones():
    with pytest.raises(InvalidMeshError) as info:
        detect_format("part.abcdefghijklmnopqrstuvwxyz")
    assert str(info.value) == (
        "unsupported mesh format 'abcdefghijklmnopqrst': use one of .obj, .off, .ply, .stl, .glb, .gltf,"
        " .zip, .3mf, .dae, .drc (.zip: a glTF with its .bin)"
    )


def test_trimesh_files_are_read_as_they_are_without_welding():
    data = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 0\nf 1 2 3\nf 4 3 2\n"  # vertex 4 repeats vertex 1
    vertices, faces = load_with_trimesh(data, "obj", "OBJ", Budget())
    assert vertices.shape == (4, 3) and faces.tolist() == [[0, 1, 2], [3, 2, 1]]


def test_a_file_trimesh_cannot_read_is_refused_with_the_first_line_of_its_error(monkeypatch):
    def broken(*args, **kwargs):
        raise ValueError("bad <COLLADA> root\nline 2 of the traceback")

    monkeypatch.setattr(scene.trimesh, "load", broken)
    message = _refusal(scene.load_with_trimesh, b"<xml/>", "dae", "COLLADA", Budget())
    assert message == "could not read the file as COLLADA: bad <COLLADA> root"


def test_placed_parts_are_counted_together_against_the_face_budget():

    ball = trimesh.creation.icosphere(1)  # 42 vertices, 80 faces
    box = trimesh.Scene()
    box.add_geometry(ball, node_name="a")
    box.add_geometry(ball.copy(), node_name="b")  # 84 vertices (under 6 x 15), 160 faces (over 8 x 15)
    with pytest.raises(InvalidMeshError) as info:
        scene_arrays(box, "3MF", Budget(15))
    assert str(info.value) == (
        "the 3MF scene (each part counted once per placement) declares 160 faces: far more than a mesh"
        " within the limit of 15 vertices can have"
    )


def _scene_of(*geometry):
    scene = trimesh.Scene()
    for g in geometry:
        scene.add_geometry(g)
    return scene


@pytest.mark.parametrize("kind", ["empty mesh", "points"])
def test_a_scene_without_a_face_holds_no_triangle_mesh(kind):

    points = np.random.default_rng(1).random((5, 3))
    if kind == "points":
        geometry = trimesh.PointCloud(points)
    else:
        geometry = trimesh.Trimesh(points, np.zeros((0, 3), int), process=False)
    message = _refusal(scene_arrays, _scene_of(geometry), "COLLADA", Budget())
    assert message == "the COLLADA file holds no triangle mesh (only points, lines or nothing)"


def test_a_point_cloud_or_a_path_is_refused_in_words():

    cloud = trimesh.PointCloud(np.random.default_rng(2).random((5, 3)))
    assert (
        _refusal(scene_arrays, cloud, "PLY", Budget())
        == "the mesh has no faces (a point cloud is not a surface)"
    )
    path = trimesh.load_path(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]))
    assert _refusal(scene_arrays, path, "DXF", Budget()) == "the DXF file holds no triangle mesh"


def test_short_is_the_first_line_of_an_error_at_most_200_characters_or_its_type():
    assert short(ValueError("  first line\nsecond")) == "first line"
    assert short(ValueError("x" * 300)) == "x" * 200
    assert short(KeyError()) == "KeyError"
    assert short(ValueError("   ")) == "ValueError"


def test_3mf_refusals_name_3mf():
    assert _refusal(read_3mf, b"not a zip", Budget()) == (
        "could not read the file as 3MF: it is not a valid zip archive"
    )
    data = bytearray(_zip({"3D/3dmodel.model": b"<model>" + b"x" * 400 + b"</model>"}, zipfile.ZIP_DEFLATED))
    start = data.index(b"PK\x03\x04") + 30 + len(b"3D/3dmodel.model")
    data[start : start + 8] = b"\xff" * 8
    assert _refusal(read_3mf, bytes(data), Budget()) == (
        "the 3MF archive is corrupt: a file inside it does not unpack"
    )


def test_a_collada_file_trimesh_cannot_read_names_collada():
    assert _refusal(read_dae, b"\x00\x01 not xml", Budget()).startswith(
        "could not read the file as COLLADA: "
    )


@pytest.fixture
def fake_draco(monkeypatch):
    decoded = {"value": None}

    def decode(data):
        if isinstance(decoded["value"], Exception):
            raise decoded["value"]
        return decoded["value"]

    monkeypatch.setitem(sys.modules, "DracoPy", SimpleNamespace(decode=decode))
    decoded["value"] = SimpleNamespace(
        points=np.arange(12, dtype=np.float32).reshape(4, 3),
        faces=np.array([[0, 1, 2], [0, 2, 3]], np.uint32),
    )
    return decoded


def test_draco_points_and_faces_come_back_as_float64_and_int64(fake_draco):

    vertices, faces = read_drc(b"DRACO....", Budget())
    assert vertices.dtype == np.float64 and vertices.shape == (4, 3)
    assert faces.dtype == np.int64 and faces.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_a_draco_point_cloud_has_no_faces(fake_draco):

    fake_draco["value"] = SimpleNamespace(points=np.zeros(12, np.float32))  # flat, no faces attribute
    vertices, faces = read_drc(b"DRACO....", Budget())
    assert vertices.shape == (4, 3) and faces.shape == (0, 3) and faces.dtype == np.int64


def test_a_draco_stream_the_decoder_refuses_is_named_with_its_error(fake_draco):
    fake_draco["value"] = RuntimeError("Failed to decode the geometry\ndetails")
    assert _refusal(read_drc, b"DRACO....", Budget()) == (
        "could not read the file as Draco: Failed to decode the geometry"
    )


def test_obj_without_vertex_lines_is_refused_in_words():
    message = _refusal(read_obj, b"f 1 2 3\n", Budget())
    assert message == "the mesh has no vertices (the file has no OBJ 'v' lines)"


def test_obj_relative_indices_count_back_from_the_vertices_defined_so_far():
    data = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 0 0 1\nf -4 -1 -2\nf 1 2 4\n"
    vertices, faces = read_obj(data, Budget())
    assert vertices.shape == (4, 3)
    assert faces.tolist() == [[0, 1, 2], [0, 3, 2], [0, 1, 3]]


def test_obj_counts_are_checked_against_the_budget_in_words():
    seven = b"v 0 0 0\n" * 7 + b"f 1 2 3\n"
    assert _refusal(read_obj, seven, Budget(1)) == (
        "the OBJ file declares 7 vertices: far more than the limit of 1 vertices could hold even after"
        " welding duplicates"
    )
    fan = b"v 0 0 0\n" * 6 + b"f 1 2 3 4 5 6\n" * 3  # 3 hexagons: 12 triangles
    assert _refusal(read_obj, fan, Budget(1)) == (
        "the OBJ file declares 12 faces: far more than a mesh within the limit of 1 vertices can have"
    )


def test_draco_refusals_in_words(fake_draco):

    assert _refusal(read_drc, b"PLY....", Budget()) == (
        "could not read the file as Draco: it does not start with 'DRACO'"
    )
    fake_draco["value"] = SimpleNamespace(points=np.zeros((7, 3)), faces=np.zeros((3, 3)))
    assert _refusal(read_drc, b"DRACO....", Budget(1)) == (
        "the Draco file declares 7 vertices: far more than the limit of 1 vertices could hold even after"
        " welding duplicates"
    )
    fake_draco["value"] = SimpleNamespace(points=np.zeros((6, 3)), faces=np.zeros((9, 3)))
    assert _refusal(read_drc, b"DRACO....", Budget(1)) == (
        "the Draco file declares 9 faces: far more than a mesh within the limit of 1 vertices can have"
    )


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"v 0 0\nv 1 1 1\nv 2 2 2\nf 1 2 3\n", "an OBJ vertex line has fewer than 3 numbers"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 x 3\n", "an OBJ face line holds something that is not a number"),
        (
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\n",
            "the mesh has no faces (the OBJ file has no 'f' lines; a point cloud or lines are not a surface)",
        ),
    ],
)
def test_obj_refusals_name_the_obj_line(data, message):
    assert _refusal(read_obj, data, Budget()) == message


def test_obj_face_counts_against_the_budget_one_per_triangle_and_a_short_line_counts_one():
    head = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    assert read_obj(head + b"f 1 2 3\n" * 8, Budget(1))[1].shape == (8, 3)  # exactly 8 x the limit
    assert _refusal(read_obj, head + b"f 1 2 3\n" * 8 + b"f 1 2\n", Budget(1)) == (
        "the OBJ file declares 9 faces: far more than a mesh within the limit of 1 vertices can have"
    )


@pytest.mark.parametrize(
    ("faces", "message"),
    [
        (b"f 0 1 2\n", "an OBJ face refers to vertex 0, but OBJ counts vertices from 1"),
        (b"f  \n", "a face has fewer than 3 corners"),
    ],
)
def test_obj_faces_without_usable_indices_are_refused_in_words(faces, message):
    assert _refusal(read_obj, b"v 0 0 0\nv 1 0 0\nv 0 1 0\n" + faces, Budget()) == message


_TETRA_OFF_VERTICES = b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n"


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"# nothing\n", "the mesh has no vertices (the OFF file is empty)"),
        (b"PLY\n", "could not read the file as OFF: it does not start with 'OFF'"),
        *[
            (
                keyword + b"\n4 1 0\n" + _TETRA_OFF_VERTICES + b"3 0 1 2\n",
                "this OFF variant (4D, n-dimensional or binary) is not supported: export plain OFF",
            )
            for keyword in (b"4OFF", b"nOFF", b"OFFBINARY")
        ],
        (
            b"OFF\n4 1 0\n" + _TETRA_OFF_VERTICES + b"3\n",
            "an OFF face line lists fewer corners than its count says",
        ),
        (
            b"OFF\n4 1 0\n" + _TETRA_OFF_VERTICES + b"2 0 1\n",
            "an OFF face line must start with its number of corners (3 or more)",
        ),
        (
            b"OFF\n4 1 0\n" + _TETRA_OFF_VERTICES + b"3.5 0 1 2\n",
            "an OFF face line must start with its number of corners (3 or more)",
        ),
        (b"OFF\n4 1 0\n" + _TETRA_OFF_VERTICES + b"3 0 1 2.5\n", "an OFF face index is not a whole number"),
        (b"OFF\n4 1 0\n0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n", "an OFF vertex line has fewer than 3 numbers"),
        (
            b"OFF\n4 1 0\n" + _TETRA_OFF_VERTICES + b"3 0 x 2\n",
            "an OFF face line holds something that is not a number",
        ),
    ],
)
def test_off_refusals_in_words(data, message):
    assert _refusal(read_off, data, Budget()) == message


def test_off_comments_are_ignored_wherever_they_are():
    data = b"OFF # a tetrahedron\n# the counts\n4 1 0\n" + _TETRA_OFF_VERTICES + b"3 0 1 2 # one face\n"
    vertices, faces = read_off(data, Budget())
    assert vertices.shape == (4, 3) and faces.tolist() == [[0, 1, 2]]


@pytest.mark.parametrize(
    ("data", "limit", "message"),
    [
        (b"OFF\n", None, "could not read the file as OFF: the counts line is missing or not numbers"),
        (
            b"OFF\n4 1 0\n",
            None,
            "the OFF header declares 4 vertices and 1 faces, but the file holds only 0 data lines:"
            " it is truncated",
        ),
        (
            b"OFF\n7 1 0\n" + _TETRA_OFF_VERTICES,
            1,
            "the OFF header declares 7 vertices: far more than the limit of 1 vertices could hold even after"
            " welding duplicates",
        ),
        (
            b"OFF\n4 9 0\n" + _TETRA_OFF_VERTICES,
            1,
            "the OFF header declares 9 faces: far more than a mesh within the limit of 1 vertices can have",
        ),
        (
            b"OFF\n4 1 0\n" + _TETRA_OFF_VERTICES + b"3 0 1 2\n3 0 1 3\n",
            None,
            "the OFF header declares 4 vertices and 1 faces, but the file holds 6 data lines: the counts are"
            " wrong or the file is corrupt",
        ),
        (
            b"OFF\n4 1 0\n0 y 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n",
            None,
            "an OFF vertex line holds something that is not a number",
        ),
    ],
)
def test_off_header_and_counts_refusals_in_words(data, limit, message):
    assert _refusal(read_off, data, Budget(limit)) == message


def _binary_stl(count: int, declared: int | None = None, header: bytes = b"\x00" * 80) -> bytes:
    import struct

    records = np.zeros(count, dtype=[("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    records["corners"] = np.arange(count * 9, dtype=np.float32).reshape(count, 3, 3)
    return header + struct.pack("<I", count if declared is None else declared) + records.tobytes()


_FACET = b"facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n"


def _ascii_stl(body: bytes, end: bytes = b"endsolid t\n") -> bytes:
    return b"solid t\n" + body + end


@pytest.mark.parametrize("lead", [b"", b"\n  "])
def test_a_short_ascii_stl_is_read_even_after_leading_blanks(lead):

    vertices, faces = read_stl(lead + _ascii_stl(_FACET), Budget())
    assert vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0]] and vertices.dtype == np.float64
    assert faces.tolist() == [[0, 1, 2]] and faces.dtype == np.int64


@pytest.mark.parametrize("count", [0, 2])
def test_a_binary_stl_of_exactly_its_declared_size_is_read(count):

    vertices, faces = read_stl(_binary_stl(count), Budget())  # count 0: exactly 84 bytes
    assert vertices.dtype == np.float64 and faces.dtype == np.int64
    np.testing.assert_array_equal(vertices, np.arange(count * 9, dtype=np.float64).reshape(-1, 3))
    assert faces.tolist() == np.arange(3 * count).reshape(-1, 3).tolist()


_NO_VERTEX_84 = b"solid t\n" + b" " * (84 - len(b"solid t\nendsolid t\n")) + b"endsolid t\n"


@pytest.mark.parametrize(
    ("data", "limit", "message"),
    [
        (_ascii_stl(_FACET, b""), None, "the ASCII STL does not end with 'endsolid': it is truncated"),
        (
            _ascii_stl(_FACET * 9),
            1,
            "the STL file declares 9 faces: far more than a mesh within the limit of 1 vertices can have",
        ),
        (_ascii_stl(b""), None, "the mesh has no vertices (the ASCII STL has no 'vertex' lines)"),
        (
            _NO_VERTEX_84,
            None,
            "the file is neither an ASCII STL (no 'vertex' lines) nor a binary STL (its header declares"
            " 175382628 triangles, 8769131484 bytes, but the file holds 84 bytes)",
        ),
        (
            _ascii_stl(b"vertex 0 0\nvertex 1 0 0\nvertex 0 1 0\n"),
            None,
            "an STL vertex line does not hold exactly 3 numbers",
        ),
        (
            _ascii_stl(b"vertex 0 x 0\nvertex 1 0 0\nvertex 0 1 0\n"),
            None,
            "an STL vertex line holds something that is not a number",
        ),
        (
            _ascii_stl(b"vertex 0 0 0\n" * 4),
            None,
            "the ASCII STL holds 4 vertex lines, not 3 per facet: it is truncated",
        ),
        (
            _binary_stl(9),
            1,
            "the STL header declares 9 faces: far more than a mesh within the limit of 1 vertices can have",
        ),
        (b"\x00\x01\x02", None, "could not read the file as STL: it is too short for a binary STL"),
        (
            b"A" * 100,
            None,
            "the STL header declares 1094795585 triangles (54739779334 bytes), but the file holds 100 bytes:"
            " it is truncated or corrupt",
        ),
        (
            _binary_stl(2, declared=3, header=b"solid" + b"\x00" * 75),  # 'solid' then NULs: binary
            None,
            "the STL header declares 3 triangles (234 bytes), but the file holds 184 bytes: it is truncated"
            " or corrupt",
        ),
    ],
)
def test_stl_refusals_in_words(data, limit, message):
    assert _refusal(read_stl, data, Budget(limit)) == message


# --- the readers' shared helpers (formats/common.py) ---------------------------------------------


def test_text_lines_drops_a_leading_bom_and_unifies_line_ends():
    assert text_lines(BOM + b"a\r\nb\rc\n") == b"a\nb\nc\n"
    assert text_lines(b"a" + BOM) == b"a" + BOM  # only a leading mark is dropped
    assert text_lines(b"plain\n") == b"plain\n"


@pytest.mark.parametrize(
    "lines",
    [
        [b"1 2 3", b"4.5 6", b"7 8 9 10"],
        [b"1 nan 3", b"4 5", b"inf 6 7"],  # a line that holds 'nan' itself: counted by splitting
        [b"1 2 3"],
        [b"1 nan nan", b"2"],  # as many NaN in the data as there are lines
    ],
)
def test_numbers_give_each_line_its_width(lines):

    values, widths = numbers(lines, "a line")
    expected = [float(t) for line in lines for t in line.split()]
    np.testing.assert_array_equal(values, expected)
    assert values.dtype == np.float64 and widths.dtype == np.int64
    assert widths.tolist() == [len(line.split()) for line in lines]


def test_numbers_and_indices_of_no_lines_are_empty():

    values, widths = numbers([], "a line")
    assert (
        values.shape == (0,)
        and values.dtype == np.float64
        and widths.shape == (0,)
        and widths.dtype == np.int64
    )
    index, corners = indices([], "a face line")
    assert index.dtype == np.int64 and corners.dtype == np.int64 and index.size == corners.size == 0


def test_indices_are_int64_and_a_zero_index_is_counted_by_splitting():
    index, corners = indices([b"1 2 3", b"4 5 6 7"], "a face line")
    assert (
        index.tolist() == [1, 2, 3, 4, 5, 6, 7] and corners.tolist() == [3, 4] and str(index.dtype) == "int64"
    )
    index, corners = indices([b"1 0 3", b"4 5 6 7"], "a face line")
    assert (
        index.tolist() == [1, 0, 3, 4, 5, 6, 7] and corners.tolist() == [3, 4] and str(index.dtype) == "int64"
    )
    index, corners = indices([b"1", b"0 0"], "a face line")  # as many non-zero values as separators
    assert index.tolist() == [1, 0, 0] and corners.tolist() == [1, 2]


@pytest.mark.parametrize("lines", [[b"1 2 x"], [b"1 2 3", b"4 y"], [b"1 nan", b"2 3x"]])
def test_a_token_that_is_not_a_number_is_refused_naming_the_line_kind(lines):
    assert (
        _refusal(numbers, lines, "a PLY vertex line")
        == "a PLY vertex line holds something that is not a number"
    )


def test_first_columns_takes_the_first_k_of_each_row():

    values = np.arange(10.0)
    np.testing.assert_array_equal(
        first_columns(values, np.array([3, 4, 3]), 3, "x"), [[0, 1, 2], [3, 4, 5], [7, 8, 9]]
    )
    np.testing.assert_array_equal(first_columns(values[:6], np.array([3, 3]), 3, "x"), [[0, 1, 2], [3, 4, 5]])
    assert _refusal(first_columns, values[:5], np.array([3, 2]), 3, "a vertex line") == (
        "a vertex line has fewer than 3 numbers"
    )


def test_fan_triangulate_fans_each_polygon_from_its_first_corner():

    faces = fan_triangulate(np.array([0, 1, 2, 3, 4, 10, 11, 12, 5, 6, 7, 8]), np.array([5, 3, 4]))
    assert faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4], [10, 11, 12], [5, 6, 7], [5, 7, 8]]
    assert fan_triangulate(np.arange(6), np.array([3, 3])).tolist() == [[0, 1, 2], [3, 4, 5]]
    assert _refusal(fan_triangulate, np.arange(5), np.array([3, 2])) == "a face has fewer than 3 corners"


def test_whole_numbers_up_to_2_53_and_nothing_else():

    out = whole_numbers(np.array([0.0, 3.0, -2.0, 2.0**53]), "an index")
    assert out.dtype == np.int64 and out.tolist() == [0, 3, -2, 2**53]
    assert whole_numbers(np.zeros(0), "an index").dtype == np.int64
    for bad in (2.5, np.nan, np.inf):
        assert _refusal(whole_numbers, np.array([1.0, bad]), "an index") == "an index is not a whole number"
    assert _refusal(whole_numbers, np.array([2.0**53 + 2]), "an index") == "an index is far out of range"
    assert _refusal(whole_numbers, np.array([-(2.0**53) - 2]), "an index") == "an index is far out of range"


# --- PLY, ASCII faces ----------------------------------------------------------------------------

_PLY_INDEX_LIST = b"property list uchar int vertex_indices\n"


def _ascii_ply(face_properties: bytes, faces: bytes) -> bytes:
    head = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    head += b"element face %d\n" % faces.count(b"\n") + face_properties + b"end_header\n"
    return head + b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n" + faces


@pytest.mark.parametrize(
    ("properties", "faces", "expected"),
    [
        (_PLY_INDEX_LIST, b"3 0 1 2\n4 0 1 2 3\n", [[0, 1, 2], [0, 1, 2], [0, 2, 3]]),
        (b"property uchar flag\n" + _PLY_INDEX_LIST, b"7 3 0 1 2\n", [[0, 1, 2]]),  # a scalar first
    ],
)
def test_ascii_ply_faces_are_read_after_their_scalar_properties(properties, faces, expected):
    assert read_ply(_ascii_ply(properties, faces), Budget())[1].tolist() == expected


@pytest.mark.parametrize(
    ("properties", "faces", "message"),
    [
        (
            b"property list uchar int foo\n" + _PLY_INDEX_LIST,
            b"1 5 3 0 1 2\n",
            "this PLY face layout (a list before the index list) is not supported",
        ),
        (_PLY_INDEX_LIST, b"3 0 x 2\n", "a PLY face line holds something that is not a number"),
        (
            b"property uchar flag\n" + _PLY_INDEX_LIST,
            b"7\n",
            "a PLY face line is shorter than its properties",
        ),
        (_PLY_INDEX_LIST, b"3.5 0 1 2\n", "a PLY face corner count is not a whole number"),
        (_PLY_INDEX_LIST, b"2 0 1\n", "a PLY face line lists fewer corners than its count says (at least 3)"),
        (
            _PLY_INDEX_LIST,
            b"4 0 1 2\n",
            "a PLY face line lists fewer corners than its count says (at least 3)",
        ),
        (_PLY_INDEX_LIST, b"3 0 1 2.5\n", "a PLY face index is not a whole number"),
    ],
)
def test_ascii_ply_face_refusals_in_words(properties, faces, message):
    assert _refusal(read_ply, _ascii_ply(properties, faces), Budget()) == message


# --- PLY, binary faces ---------------------------------------------------------------------------


def _binary_ply(face_count: int, faces: bytes) -> bytes:
    import struct

    head = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
    head += (
        b"property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n"
        % face_count
    )
    return head + struct.pack("<12f", 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1) + faces


def test_binary_ply_faces_of_mixed_sizes_are_fanned():
    import struct

    data = _binary_ply(2, struct.pack("<B3i", 3, 0, 1, 2) + struct.pack("<B4i", 4, 0, 1, 2, 3))
    assert read_ply(data, Budget())[1].tolist() == [[0, 1, 2], [0, 1, 2], [0, 2, 3]]


@pytest.mark.parametrize(
    ("count", "faces", "message"),
    [
        (
            3,
            b"\x03",
            "the PLY header declares 3 'face' elements, but only 1 bytes are left for them:"
            " the file is truncated",
        ),
        (2, b"\x00\x00", "a PLY face has fewer than 3 corners"),  # ends exactly where empty lists would
    ],
)
def test_binary_ply_face_refusals_in_words(count, faces, message):
    assert _refusal(read_ply, _binary_ply(count, faces), Budget()) == message


# --- PLY, header and ASCII body ------------------------------------------------------------------

_PLY_HEAD = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
_PLY_VERTICES = b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n"


@pytest.mark.parametrize(
    "data",
    [
        b"ply\ncomment\nobj_info x\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        b"property float z\nelement face 1\n"
        + _PLY_INDEX_LIST
        + b"end_header\n"
        + _PLY_VERTICES
        + b"3 0 1 2\n",
        b"ply\nformat ascii 1.0\nelement face 1\n" + _PLY_INDEX_LIST + b"element vertex 4\nproperty float x\n"
        b"property float y\nproperty float z\nend_header\n3 0 1 2\n" + _PLY_VERTICES,  # faces first
        _PLY_HEAD
        + b"element edge 1\nproperty int vertex1\nproperty int vertex2\nelement face 1\n"
        + _PLY_INDEX_LIST
        + b"end_header\n"
        + _PLY_VERTICES
        + b"0 1\n3 0 1 2\n",  # an element between
    ],
)
def test_ascii_ply_headers_with_comments_and_elements_in_any_order_are_read(data):
    vertices, faces = read_ply(data, Budget())
    assert vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]] and faces.tolist() == [[0, 1, 2]]


def _ply_with_end_header_at(offset: int) -> bytes:
    prefix = b"ply\nformat ascii 1.0\ncomment "
    rest = (
        b"\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\n"
        + _PLY_INDEX_LIST
    )
    data = (
        prefix
        + b"a" * (offset - len(prefix) - len(rest))
        + rest
        + b"end_header\n"
        + _PLY_VERTICES
        + b"3 0 1 2\n"
    )
    assert data.find(b"end_header") == offset
    return data


def test_a_ply_header_may_end_at_1_mib_and_no_later():
    assert read_ply(_ply_with_end_header_at(1 << 20), Budget())[1].tolist() == [[0, 1, 2]]
    assert _refusal(read_ply, _ply_with_end_header_at((1 << 20) + 1), Budget()) == (
        "could not read the file as PLY: the header has no 'end_header'"
    )


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"PLX\nformat ascii 1.0\n", "could not read the file as PLY: it does not start with 'ply'"),
        (_PLY_HEAD, "could not read the file as PLY: the header has no 'end_header'"),
        (
            _PLY_HEAD + b"element face 1\nproperty floaty w\n" + _PLY_INDEX_LIST + b"end_header\n",
            "could not read the file as PLY: bad header line 'property floaty w'",
        ),
        (
            _PLY_HEAD
            + b"element face 1\nproperty "
            + b"q" * 80
            + b" w\n"
            + _PLY_INDEX_LIST
            + b"end_header\n",
            "could not read the file as PLY: bad header line 'property " + "q" * 51 + "'",
        ),
        (
            b"ply\nformat binary_middle_endian_with_a_very_long_name 1.0\nelement vertex 4\nend_header\n",
            "could not read the file as PLY: unknown format 'binary_middle_endian_with_a_ve'",
        ),
        (
            b"ply\nelement vertex 4\nproperty float x\nend_header\n",
            "could not read the file as PLY: unknown format ''",
        ),
        (
            _PLY_HEAD + b"element face 1\nproperty int a\nend_header\n" + _PLY_VERTICES + b"3\n",
            "the PLY face element has no vertex index list",
        ),
        (
            _PLY_HEAD
            + b"element face 2\n"
            + _PLY_INDEX_LIST
            + b"end_header\n"
            + _PLY_VERTICES
            + b"3 0 1 2\n",
            "the PLY header declares 6 element lines, but the file holds 5: it is truncated",
        ),
        (
            _PLY_HEAD
            + b"element face 1\n"
            + _PLY_INDEX_LIST
            + b"end_header\n"
            + _PLY_VERTICES
            + b"3 0 1 2\n3 0 1 3\n",
            "the PLY header declares 5 element lines, but the file holds 6: the counts are wrong",
        ),
        (
            _PLY_HEAD
            + b"element face 1\n"
            + _PLY_INDEX_LIST
            + b"end_header\n0 x 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n",
            "a PLY vertex line holds something that is not a number",
        ),
        (
            _PLY_HEAD
            + b"element face 1\n"
            + _PLY_INDEX_LIST
            + b"end_header\n0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n",
            "a PLY vertex line does not hold one number per property",
        ),
    ],
)
def test_ply_header_and_ascii_body_refusals_in_words(data, message):
    assert _refusal(read_ply, data, Budget()) == message


def _binary_ply_with_extras(padding: bytes = b"", vertex_bytes: int | None = None) -> bytes:
    """Vertices with a colour byte, a texture element of lists to skip, faces with a flag byte first."""
    import struct

    head = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        b"property float z\nproperty uchar red\nelement texture 2\nproperty list uchar float uv\n"
        b"element face 2\n"
        b"property uchar flags\nproperty list uchar int vertex_indices\nend_header\n"
    )
    vertices = b"".join(struct.pack("<3fB", *p, 7) for p in [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)])
    if vertex_bytes is not None:
        return head + vertices[:vertex_bytes]
    texture = struct.pack("<B2f", 2, 0.5, 0.5) + struct.pack("<B", 0)
    faces = struct.pack("<BB3i", 9, 3, 0, 1, 2) + struct.pack("<BB3i", 9, 3, 0, 2, 3)
    return head + vertices + texture + faces + padding


@pytest.mark.parametrize("padding", [b"", b"\x00" * 64])
def test_binary_ply_skips_list_elements_reads_past_scalars_and_allows_64_bytes_of_padding(padding):

    vertices, faces = read_ply(_binary_ply_with_extras(padding), Budget())
    assert vertices.dtype == np.float64 and vertices.tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    assert faces.dtype == np.int64 and faces.tolist() == [[0, 1, 2], [0, 2, 3]]


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (_binary_ply_with_extras(b"\x00" * 65), "the PLY file holds 65 bytes more than its header declares"),
        (
            _binary_ply_with_extras(vertex_bytes=20),
            "the PLY header declares 4 'vertex' elements, but only 20 bytes are left for them:"
            " the file is truncated",
        ),
    ],
)
def test_binary_ply_size_refusals_in_words(data, message):
    assert _refusal(read_ply, data, Budget()) == message


# --- PLY, binary reader edge cases ---------------------------------------------------------------


def _ply_bytes(
    vertices: list[tuple[float, float, float]], face_decl: bytes, faces: bytes, count: int
) -> bytes:
    """Binary little-endian PLY: float x, y, z vertices, then a face element declared by face_decl."""
    import struct

    head = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
        % len(vertices)
    )
    head += b"property float z\nelement face %d\n%send_header\n" % (count, face_decl)
    return head + b"".join(struct.pack("<3f", *v) for v in vertices) + faces


_TRIANGLE = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]
_UCHAR_INT = b"property list uchar int vertex_indices\n"


def test_a_binary_ply_whose_vertex_bytes_spell_end_header_is_read():
    import struct

    odd = struct.unpack("<3f", b"end_header\x00\x00")  # the header ends at the first end_header
    data = _ply_bytes([*_TRIANGLE, odd], _UCHAR_INT, struct.pack("<B3i", 3, 0, 1, 3), 1)
    vertices, faces = read_ply(data, Budget())
    assert vertices.tolist()[3] == list(odd) and faces.tolist() == [[0, 1, 3]]


def test_an_ascii_ply_ending_at_end_header_has_no_element_lines():
    data = _PLY_HEAD + b"element face 1\n" + _PLY_INDEX_LIST + b"end_header"
    assert _refusal(read_ply, data, Budget()) == (
        "the PLY header declares 5 element lines, but the file holds 0: it is truncated"
    )


def test_binary_ply_vertices_last_may_end_exactly_at_the_end_of_the_file():
    import struct

    data = (
        b"ply\nformat binary_little_endian 1.0\nelement face 1\n"
        + _UCHAR_INT
        + b"element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
        + struct.pack("<B3i", 3, 0, 1, 2)
        + b"".join(struct.pack("<3f", *v) for v in _TRIANGLE)
    )
    vertices, faces = read_ply(data, Budget())
    assert vertices.tolist() == [list(v) for v in _TRIANGLE] and faces.tolist() == [[0, 1, 2]]


def test_binary_ply_with_no_byte_after_the_header_says_0_bytes():
    assert _refusal(read_ply, _binary_ply_with_extras(vertex_bytes=0), Budget()) == (
        "the PLY header declares 4 'vertex' elements, but only 0 bytes are left for them:"
        " the file is truncated"
    )


@pytest.mark.parametrize(
    ("decl", "faces", "count", "message"),
    [
        (  # 4 faces of at least a 4-byte count each cannot fit in 8 bytes
            b"property list int int vertex_indices\n",
            b"\x03\x00\x00\x00\x00\x00\x00\x00",
            4,
            "the PLY header declares 4 'face' elements, but only 8 bytes are left for them:"
            " the file is truncated",
        ),
        (  # one face whose indices are cut short
            _UCHAR_INT,
            b"\x03\x00\x00\x00\x00",
            1,
            "the PLY header declares 1 'face' elements, but only 5 bytes are left for them:"
            " the file is truncated",
        ),
        (  # mixed sizes (the record walk), the second face with 2 corners
            _UCHAR_INT,
            b"\x03" + b"\x00" * 12 + b"\x02" + b"\x00" * 8,
            2,
            "a PLY face has fewer than 3 corners",
        ),
    ],
)
def test_binary_ply_face_truncation_and_corner_refusals_in_words(decl, faces, count, message):
    assert _refusal(read_ply, _ply_bytes(_TRIANGLE, decl, faces, count), Budget()) == message


def test_binary_ply_mixed_size_faces_are_int64():
    import struct

    data = _binary_ply(2, struct.pack("<B3i", 3, 0, 1, 2) + struct.pack("<B4i", 4, 0, 1, 2, 3))
    faces = read_ply(data, Budget())[1]
    assert faces.dtype == np.int64 and faces.tolist() == [[0, 1, 2], [0, 1, 2], [0, 2, 3]]


def test_a_binary_ply_of_one_triangle_and_nothing_after_it_is_read():
    import struct

    data = _ply_bytes(_TRIANGLE, _UCHAR_INT, struct.pack("<B3i", 3, 0, 1, 2), 1)
    assert read_ply(data, Budget())[1].tolist() == [[0, 1, 2]]


def test_a_binary_ply_face_with_a_scalar_equal_to_its_corner_count_is_read():
    import struct

    decl = b"property uchar flags\n" + _UCHAR_INT
    data = _ply_bytes(_TRIANGLE, decl, struct.pack("<BB3i", 3, 3, 0, 1, 2), 1)
    assert read_ply(data, Budget())[1].tolist() == [[0, 1, 2]]


def test_a_binary_ply_face_of_112_corners_is_fanned_from_its_own_bytes():
    import math

    ring = [(math.cos(i / 18), math.sin(i / 18), 0.0) for i in range(112)]  # 112 == ord("p"), as "ply"
    data = _ply_bytes(ring, b"property list uchar uchar vertex_indices\n", bytes([112, *range(112)]), 1)
    faces = read_ply(data, Budget())[1]
    assert faces.tolist() == [[0, i, i + 1] for i in range(1, 111)]


# --- glTF buffers --------------------------------------------------------------------------------

_SMALL_BUDGET = SimpleNamespace(unpacked_bytes=lambda: 30)  # what _buffers asks of a Budget


def _gltf_buffers(buffers, chunk=None, files=None, what="glTF"):
    return _buffers({"buffers": buffers} if buffers is not None else {}, chunk, files, what, _SMALL_BUDGET)


def test_gltf_buffers_from_data_uris_chunks_and_files():
    assert _gltf_buffers(None) == []  # no "buffers" at all: none
    assert _gltf_buffers([{"byteLength": 3}], chunk=b"abc", what="GLB") == [b"abc"]  # exactly its length
    # base64 past a comma or a line break: the characters outside the alphabet are dropped
    assert _gltf_buffers([{"uri": "data:;base64,AAAA,AAAA"}]) == [b"\x00" * 6]
    assert _gltf_buffers([{"uri": "data:;base64,AAAA\nAAAA"}]) == [b"\x00" * 6]
    assert _gltf_buffers([{"uri": "x.bin"}], files={"x.bin": b"xyz"}.__getitem__) == [b"xyz"]


def test_a_gltf_data_uri_may_be_up_to_the_unpacked_budget():
    uri = "data:;base64," + "A" * 28  # 41 characters: 41 * 3 // 4 == 30 (30.75 unrounded)
    assert _gltf_buffers([{"uri": uri}]) == [b"\x00" * 21]
    assert _refusal(_gltf_buffers, [{"uri": uri + "AA"}]) == "the glTF buffer 0 is larger than allowed"


@pytest.mark.parametrize(
    ("buffers", "chunk", "what", "message"),
    [
        ([{"byteLength": 1}], None, "glTF", "the glTF buffer 0 has no data (no URI and no binary chunk)"),
        (
            [{"byteLength": 1}, {"byteLength": 1}],
            b"a",
            "GLB",
            "the GLB buffer 1 has no data (no URI and no binary chunk)",
        ),
        ([{"uri": "data:AAAA"}], None, "glTF", "the glTF buffer 0 has a malformed data: URI"),
        ([{"uri": "data:;base64,AAA"}], None, "glTF", "the glTF buffer 0 has a malformed data: URI"),
        (
            [{"uri": "x.bin"}],
            None,
            "glTF",
            "the glTF refers to an external file 'x.bin'; upload a .zip holding both,"
            " or a self-contained .gltf or GLB",
        ),
        (
            [{"uri": "y" * 100}],
            b"",
            "GLB",
            "the GLB refers to an external file '" + "y" * 80 + "'; upload a .zip holding both,"
            " or a self-contained GLB",
        ),
        (
            [{"byteLength": 4}],
            b"abc",
            "GLB",
            "the GLB buffer 0 declares 4 bytes, but holds 3: it is truncated",
        ),
    ],
)
def test_gltf_buffer_refusals_in_words(buffers, chunk, what, message):
    assert _refusal(_gltf_buffers, buffers, chunk, None, what) == message


def test_a_binary_ply_face_record_missing_entirely_is_truncated_in_words():
    import struct

    data = _ply_bytes(_TRIANGLE, _UCHAR_INT, struct.pack("<B3i", 3, 0, 1, 2), 2)  # the second face is absent
    assert _refusal(read_ply, data, Budget()) == (
        "the PLY header declares 2 'face' elements, but only 13 bytes are left for them:"
        " the file is truncated"
    )


@pytest.mark.parametrize(
    ("vertex_properties", "vertex_lines"),
    [
        (b"property float x\nproperty float y\nproperty float w\n", b"0 0 0\n1 0 0\n0 1 0\n"),  # no z
        (  # a list among the vertex properties
            b"property float x\nproperty float y\nproperty float z\nproperty list uchar int extra\n",
            b"0 0 0 0\n1 0 0 0\n0 1 0 0\n",
        ),
    ],
)
def test_a_ply_vertex_element_without_xyz_or_with_a_list_is_refused_in_words(vertex_properties, vertex_lines):
    data = (
        b"ply\nformat ascii 1.0\nelement vertex 3\n"
        + vertex_properties
        + b"element face 1\n"
        + _PLY_INDEX_LIST
        + b"end_header\n"
        + vertex_lines
        + b"3 0 1 2\n"
    )
    assert _refusal(read_ply, data, Budget()) == "the PLY vertex element has no x, y, z properties"


def _ascii_ply_with_edges(count: bytes) -> bytes:
    return (
        _PLY_HEAD
        + b"element edge "
        + count
        + b"\nproperty int a\nelement face 1\n"
        + _PLY_INDEX_LIST
        + b"end_header\n"
        + _PLY_VERTICES
        + b"3 0 1 2\n"
    )


def test_a_ply_element_may_declare_up_to_64_per_byte_of_the_file():
    size = len(_ascii_ply_with_edges(b"00000"))
    assert 10000 <= 64 * size < 100000  # five digits either way
    assert _refusal(read_ply, _ascii_ply_with_edges(b"%d" % (64 * size)), Budget()) == (
        f"the PLY header declares {64 * size + 5} element lines, but the file holds 5: it is truncated"
    )
    assert _refusal(read_ply, _ascii_ply_with_edges(b"%d" % (64 * size + 1)), Budget()) == (
        f"the PLY header declares {64 * size + 1} 'edge' elements: corrupt"
    )


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            b"ply\nformat ascii 1.0\nelement face 1\n" + _PLY_INDEX_LIST + b"end_header\n3 0 1 2\n",
            "the mesh has no vertices (the PLY file has no 'vertex' element)",
        ),
        (
            _PLY_HEAD + b"end_header\n" + _PLY_VERTICES,
            "the mesh has no faces (a point cloud is not a surface)",
        ),
        (
            _PLY_HEAD + b"element face 0\n" + _PLY_INDEX_LIST + b"end_header\n" + _PLY_VERTICES,
            "the mesh has no faces (a point cloud is not a surface)",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n",
            "the file is corrupt: the PLY header declares a negative count",
        ),
        (
            _PLY_HEAD + b"element face -1\n" + _PLY_INDEX_LIST + b"end_header\n",
            "the file is corrupt: the PLY header declares a negative count",
        ),
    ],
)
def test_ply_element_refusals_in_words(data, message):
    assert _refusal(read_ply, data, Budget()) == message


def test_ply_declared_counts_are_checked_against_the_budget_in_words():
    budget = Budget(max_vertices=1)
    many = RAW_VERTEX_FACTOR + 1
    head = b"ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\n"
    assert _refusal(read_ply, head % many + b"end_header\n", budget) == (
        f"the PLY header declares {many} vertices: far more than the limit of 1 vertices could hold"
        " even after welding duplicates"
    )
    faces = FACE_FACTOR + 1
    data = head % 3 + b"element face %d\n" % faces + _PLY_INDEX_LIST + b"end_header\n"
    assert _refusal(read_ply, data, budget) == (
        f"the PLY header declares {faces} faces: far more than a mesh within the limit of 1 vertices can have"
    )


# --- glTF canonical GLB --------------------------------------------------------------------------


def test_the_canonical_glb_is_a_well_formed_glb_with_8_byte_aligned_buffers():
    import json
    import struct

    doc = {
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
        "materials": [{}],
        "textures": [{}],
        "images": [{"uri": "gone.png"}],
        "samplers": [{}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 1, "byteLength": 2},
            {"buffer": 1, "byteLength": 5},
            {"buffer": 2, "byteOffset": 2, "byteLength": 1},
        ],
    }
    buffers = [b"abc", b"defgh", b"ijklmnopq"]
    glb = _canonical_glb(doc, buffers)
    magic, version, length = struct.unpack_from("<4sII", glb)
    assert (magic, version, length) == (b"glTF", 2, len(glb))
    json_length, json_type = struct.unpack_from("<II", glb, 12)
    assert json_type == 0x4E4F534A and json_length % 4 == 0
    out = json.loads(glb[20 : 20 + json_length])
    bin_at = 20 + json_length
    bin_length, bin_type = struct.unpack_from("<II", glb, bin_at)
    assert bin_type == 0x004E4942 and bin_length % 4 == 0 and bin_at + 8 + bin_length == len(glb)
    blob = glb[bin_at + 8 :]
    assert blob == b"abc" + b"\0" * 5 + b"defgh" + b"\0" * 3 + b"ijklmnopq" + b"\0" * 3
    assert out["buffers"] == [{"byteLength": 25}]
    assert [(v["buffer"], v["byteOffset"]) for v in out["bufferViews"]] == [(0, 1), (0, 8), (0, 18)]
    assert not {"materials", "textures", "images", "samplers"} & set(out)
    assert out["meshes"][0]["primitives"] == [{"attributes": {"POSITION": 0}}]


def test_a_canonical_glb_of_a_document_without_views_or_meshes_has_no_binary_chunk():
    import json
    import struct

    glb = _canonical_glb({"asset": {"version": "2.0"}}, [])
    json_length, json_type = struct.unpack_from("<II", glb, 12)
    assert len(glb) == 20 + json_length and struct.unpack_from("<I", glb, 8)[0] == len(glb)
    out = json.loads(glb[20:])
    assert out == {"asset": {"version": "2.0"}, "bufferViews": [], "buffers": [], "meshes": []}


# --- glTF checks before any array is read --------------------------------------------------------


@pytest.mark.parametrize("name", ["EXT_meshopt_compression", "KHR_meshopt_compression"])
@pytest.mark.parametrize("key", ["extensionsUsed", "extensionsRequired"])
def test_meshopt_is_refused_whether_used_or_required_naming_the_extension(name, key):
    with pytest.raises(UnsupportedFormatError) as info:
        _check_extensions({key: ["KHR_draco_mesh_compression", name]})
    assert str(info.value) == (
        f"unsupported mesh format: meshopt-compressed glTF ({name}) is not supported:"
        " export it without meshopt compression (Draco is fine), or as OBJ, PLY, STL, GLB or 3MF"
    )


def test_gpu_instancing_is_refused_only_when_required():
    _check_extensions({})
    _check_extensions({"extensionsUsed": ["EXT_mesh_gpu_instancing", "KHR_draco_mesh_compression"]})
    with pytest.raises(UnsupportedFormatError) as info:
        _check_extensions({"extensionsRequired": ["KHR_draco_mesh_compression", "EXT_mesh_gpu_instancing"]})
    assert str(info.value) == (
        "unsupported mesh format: GPU instancing (EXT_mesh_gpu_instancing) is not supported:"
        " apply the instances and export again"
    )


_VIEW_PAST = "a glTF buffer view runs past the end of its buffer: the file is corrupt"


def test_gltf_buffer_views_must_lie_inside_their_buffer():
    buffers = [b"", b"x" * 10]
    _check_views({}, buffers)
    _check_views({"bufferViews": [{"buffer": 1, "byteOffset": 4, "byteLength": 6}]}, buffers)
    _check_views({"bufferViews": [{"buffer": 1, "byteLength": 10}]}, buffers)
    for view in (
        {"buffer": 1, "byteOffset": 4, "byteLength": 7},
        {"buffer": 1, "byteLength": 11},
        {"buffer": 0, "byteLength": 1},
    ):
        assert _refusal(_check_views, {"bufferViews": [view]}, buffers) == _VIEW_PAST
    view = {"buffer": 1, "byteOffset": -1, "byteLength": 1}
    assert _refusal(_check_views, {"bufferViews": [view]}, buffers) == (
        "the glTF byteOffset is not a whole number in range: -1"
    )


def _accessor_doc(accessor: dict, view_length: int, stride: int | None = None) -> dict:
    view = {"buffer": 0, "byteLength": view_length}
    if stride is not None:
        view["byteStride"] = stride
    return {"bufferViews": [view], "accessors": [dict(accessor, bufferView=0)]}


def test_gltf_accessors_must_fit_their_view_for_every_component_type_and_width():
    sizes = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
    widths = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
    buffers = [b"\0" * 1024]
    for component, size in sizes.items():
        for kind, width in widths.items():
            accessor = {"componentType": component, "type": kind, "count": 1}
            _check_views(_accessor_doc(accessor, size * width), buffers)
            assert _refusal(_check_views, _accessor_doc(accessor, size * width - 1), buffers) == (
                f"a glTF accessor declares 1 elements ({size * width} bytes), more than its buffer view"
                f" holds ({size * width - 1} bytes): the file is corrupt"
            )


def test_gltf_accessor_sizes_count_the_offset_and_the_stride():
    buffers = [b"\0" * 1024]
    accessor = {"componentType": 5126, "type": "VEC3", "count": 2, "byteOffset": 4}
    _check_views(_accessor_doc(accessor, 28), buffers)  # 4 + 12 + 12
    _check_views(_accessor_doc(accessor, 28, stride=0), buffers)  # a stride of 0: packed
    assert _refusal(_check_views, _accessor_doc(accessor, 27), buffers) == (
        "a glTF accessor declares 2 elements (28 bytes), more than its buffer view holds (27 bytes):"
        " the file is corrupt"
    )
    _check_views(_accessor_doc(accessor, 32, stride=16), buffers)  # 4 + 16 + 12
    assert _refusal(_check_views, _accessor_doc(accessor, 31, stride=16), buffers) == (
        "a glTF accessor declares 2 elements (32 bytes), more than its buffer view holds (31 bytes):"
        " the file is corrupt"
    )


def test_gltf_accessors_without_a_view_or_elements_are_not_measured_and_negative_counts_refused():
    buffers = [b""]
    _check_views({"accessors": [{"componentType": 5126, "type": "VEC3", "count": 5}]}, buffers)
    _check_views({"accessors": [{"bufferView": 7, "componentType": 1, "type": "?", "count": 0}]}, buffers)
    assert _refusal(_check_views, {"accessors": [{"count": -1}]}, buffers) == (
        "the glTF accessor count is not a whole number in range: -1"
    )
    assert _refusal(_check_views, {"accessors": [{"count": float("inf")}]}, buffers) == (
        "the glTF accessor count is not a whole number in range: inf"
    )


def _recorder():
    calls = []
    budget = SimpleNamespace(
        vertices=lambda n, what: calls.append(("vertices", n, what)),
        faces=lambda n, what: calls.append(("faces", n, what)),
    )
    return budget, calls


_SCENE = "the glTF scene (each part counted once per placement)"


def _pos(count: int) -> dict:
    return {"count": count, "type": "VEC3", "componentType": 5126}


def _idx(count: int, component: int = 5125) -> dict:
    return {"count": count, "type": "SCALAR", "componentType": component}


def test_gltf_counts_each_mesh_once_per_node_that_places_it():
    doc = {
        "accessors": [_pos(4), _idx(7), _pos(5)],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]},  # 4 vertices, 7 // 3 faces
            {"primitives": [{"attributes": {"POSITION": 2}}, {"attributes": {"POSITION": 2}}]},  # 10, 2 x 1
        ],
        "nodes": [{"mesh": 0, "children": [1, 1]}, {"mesh": 1}, {"mesh": 0}, {}],
    }
    budget, calls = _recorder()
    _check_counts(doc, budget)
    # roots 0, 2 and 3 (no scene); node 1 is placed twice through node 0
    assert calls == [("vertices", 4 + 2 * 10 + 4, _SCENE), ("faces", 2 + 2 * 2 + 2, _SCENE)]


@pytest.mark.parametrize(
    ("placements", "message"),
    [
        (10_000, None),
        (
            10_001,
            "the glTF scene (each part counted once per placement) places 10001 meshes, more than the"
            " limit of 10000: merge the instances into one mesh and export again",
        ),
    ],
)
def test_gltf_scenes_may_place_ten_thousand_meshes_and_no_more(placements, message):
    doc = {
        "accessors": [_pos(3), _idx(3)],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": [{"mesh": 0}] * placements,
    }
    budget, calls = _recorder()
    if message is None:
        _check_counts(doc, budget)
        assert [c[1] for c in calls] == [3 * placements, placements]
    else:
        assert _refusal(_check_counts, doc, budget) == message


@pytest.mark.parametrize(
    ("index", "words"),
    [(_idx(3, 5126), "FLOAT SCALAR"), (_idx(3, 5122), "SHORT SCALAR"), (dict(_idx(3), type="VEC3"), "VEC3")],
)
def test_gltf_indices_must_be_unsigned_integer_scalars(index, words):
    doc = {
        "accessors": [_pos(3), index],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
    }
    message = _refusal(_check_counts, doc, _recorder()[0])
    assert words in message and "indices must be unsigned integers" in message


def test_gltf_instances_follow_the_chosen_scene_and_multiply_shared_children():
    nodes = [{"children": [1, 1]}, {"children": [2, 2]}, {}]
    assert _instances({"nodes": nodes, "scenes": [{"nodes": [0]}]}) == [1, 2, 4]
    assert _instances({"nodes": nodes, "scenes": [{"nodes": [1]}, {"nodes": [0]}]}) == [0, 1, 2]
    assert _instances({"nodes": nodes, "scenes": [{"nodes": [1]}, {"nodes": [0]}], "scene": 1}) == [1, 2, 4]
    assert _instances({"nodes": nodes, "scenes": [{}]}) == [0, 0, 0]
    assert _instances({"nodes": nodes}) == [1, 2, 4]  # no scene: the unparented nodes are the roots
    assert _instances({}) == []
    chain = [{"children": [i + 1, i + 1]} for i in range(40)] + [{}]
    assert _instances({"nodes": chain})[-1] == MAX_INSTANCES + 1  # capped, not 2 ** 40


@pytest.mark.parametrize(
    "nodes", [[{"children": [1]}, {"children": [0]}], [{"children": [0]}], [{}, {"children": [1]}]]
)
def test_a_gltf_node_cycle_is_refused_in_words(nodes):
    assert (
        _refusal(_instances, {"nodes": nodes}) == "the glTF node hierarchy has a cycle: the file is corrupt"
    )


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"{", "could not read the file as glTF: its JSON is invalid"),
        (b"\xff{}", "could not read the file as glTF: its JSON is invalid"),
        (b"[" * 100000 + b"]" * 100000, "could not read the file as glTF: its JSON is invalid"),
        (b"[]", "could not read the file as glTF: its JSON is not an object"),
        (b"\xef\xbb\xbf{}", "the glTF file holds no triangle mesh (it has no meshes)"),  # a BOM is fine
        (b'{"meshes": []}', "the glTF file holds no triangle mesh (it has no meshes)"),
        (
            b'{"meshes": [{"primitives": [{"attributes": {}}]}]}',
            "could not read the file as glTF: its JSON structure is invalid",
        ),
    ],
)
def test_gltf_json_refusals_in_words(data, message):
    assert _refusal(read_gltf, data, Budget()) == message


# --- GLB container -------------------------------------------------------------------------------


def _glb_of(*chunks: tuple[int, bytes], version: int = 2, extra: int = 0) -> bytes:
    import struct

    body = b"".join(struct.pack("<II", len(data), kind) + data for kind, data in chunks)
    return b"glTF" + struct.pack("<II", version, 12 + len(body) + extra) + body


_J, _B = 0x4E4F534A, 0x004E4942


def test_glb_chunks_first_json_and_first_binary_with_or_without_padding():
    doc, chunk = _split_glb(_glb_of((_J, b'{"a": 1}'), (7, b"skip"), (_B, b"bin!"), (_J, b"{}"), (_B, b"no")))
    assert doc == {"a": 1} and chunk == b"bin!"
    assert _split_glb(_glb_of((_J, b"{}  "))) == ({}, None)
    # a 2-byte JSON chunk and the binary chunk right after it (padding omitted), or after 2 bytes of it
    assert _split_glb(_glb_of((_J, b"{}"), (_B, b"xyz"))) == ({}, b"xyz")
    padded = _glb_of((_J, b"{}")) + b"  " + _glb_of((_B, b"xyz"))[12:]
    padded = padded[:8] + len(padded).to_bytes(4, "little") + padded[12:]
    assert _split_glb(padded) == ({}, b"xyz")


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            b"glTF" + b"\x02\0\0\0" + b"\x13\0\0\0" + b"\0" * 7,
            "could not read the file as GLB: it does not start with 'glTF'",
        ),
        (
            b"glTX" + b"\x02\0\0\0" + b"\x14\0\0\0" + b"\0" * 8,
            "could not read the file as GLB: it does not start with 'glTF'",
        ),
        (_glb_of((_J, b"")), "could not read the file as GLB: its JSON is invalid"),  # 20 bytes: read
        (
            _glb_of((_J, b"{}"), extra=2),
            "the GLB header declares 24 bytes, but the file holds 22: it is corrupt",
        ),
        (_glb_of((_J, b"{}"))[:-1], "the GLB header declares 22 bytes, but the file holds 21: it is corrupt"),
        (_glb_of((_B, b"1234")), "could not read the file as GLB: it has no JSON chunk"),
        (
            _glb_of((_J, b"{}"), (_B, b"")),
            "the GLB file holds no triangle mesh (it has no meshes)",
        ),
    ],
)
def test_glb_container_refusals_in_words(data, message):
    assert _refusal(read_glb, data, Budget()) == message


def test_a_glb_chunk_past_the_end_and_glb_1_are_refused_in_words():
    import struct

    cut = b"glTF" + struct.pack("<II", 2, 24) + struct.pack("<II", 5, _J) + b"{}  "  # 5 declared, 4 there
    assert _refusal(read_glb, cut, Budget()) == "a GLB chunk runs past the end of the file: it is truncated"
    with pytest.raises(UnsupportedFormatError) as info:
        read_glb(_glb_of((_J, b"{}"), version=1), Budget())
    assert str(info.value) == "unsupported mesh format: glTF 1.0 is not supported: export glTF 2.0"


def test_a_gltf_buffer_without_a_byte_length_may_be_empty():
    assert _gltf_buffers([{"uri": "data:;base64,"}]) == [b""]
    assert _gltf_buffers([{}], chunk=b"", what="GLB") == [b""]


# --- glTF in a .zip ------------------------------------------------------------------------------


def _tetra_gltf(uri: str) -> bytes:
    """test_formats' glTF tetrahedron, its buffer in the file at `uri`."""
    import json

    doc, blob = tetra_doc([{"mesh": 0}])
    doc["buffers"] = [{"byteLength": len(blob), "uri": uri}]
    return json.dumps(doc).encode()


def _tetra_bin() -> bytes:
    return tetra_doc([{"mesh": 0}])[1]


def test_a_zip_with_one_gltf_beside_mac_leftovers_and_folders_reads_its_files_relative_to_it():
    data = _zip(
        {
            "m/": b"",
            "__MACOSX/m/._a.gltf": b"junk",
            "m/._b.GLTF": b"junk",
            "m/sub/a.GLTF": _tetra_gltf("../bin/t%20x.bin"),
            "m/bin/t x.bin": _tetra_bin(),
        }
    )
    vertices, faces = read_zip(data, Budget())
    assert len(vertices) == 4 and len(faces) == 4


@pytest.mark.parametrize(
    ("members", "message"),
    [
        (
            {"a.txt": b"x", "d.gltf/": b""},
            "the .zip holds no .gltf or .glb file (a .zip upload is a glTF with its files)",
        ),
        (
            {f"m{i}.glb": b"x" for i in range(6)},
            "the .zip holds several models (m0.glb, m1.glb, m2.glb, m3.glb, m4.glb): upload one per file",
        ),
        ({"a.gltf": _tetra_gltf("t.bin")}, "the glTF refers to 't.bin', which is not in the .zip"),
        (
            {"a.gltf": _tetra_gltf("u" * 100)},
            "the glTF refers to '" + "u" * 80 + "', which is not in the .zip",
        ),
        ({"a.glb": b"glTF"}, "could not read the file as GLB: it does not start with 'glTF'"),
        ({"a.gltf": b"[]"}, "could not read the file as glTF: its JSON is not an object"),
    ],
)
def test_zip_refusals_in_words(members, message):
    assert _refusal(read_zip, _zip(members), Budget()) == message


def test_a_glb_in_a_zip_uses_its_binary_chunk():
    import json
    import struct

    doc = json.loads(_tetra_gltf(""))
    del doc["buffers"][0]["uri"]
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), _J) + text + struct.pack("<II", 72, _B) + _tetra_bin()
    glb = b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body
    vertices, faces = read_zip(_zip({"x/model.glb": glb}), Budget())
    assert len(vertices) == 4 and len(faces) == 4


def test_a_gltf_mesh_without_primitives_counts_nothing():
    budget, calls = _recorder()
    _check_counts({"meshes": [{}], "nodes": [{"mesh": 0}, {"mesh": 0}]}, budget)
    assert calls == [("vertices", 0, _SCENE), ("faces", 0, _SCENE)]


def test_gltf_instances_wait_for_every_parent_and_count_a_root_listed_twice():
    # node 2 has two parents; its child 3 is counted only once both have been added
    assert _instances({"nodes": [{"children": [2]}, {"children": [2]}, {"children": [3]}, {}]}) == [
        1,
        1,
        2,
        2,
    ]
    assert _instances({"nodes": [{}], "scenes": [{"nodes": [0, 0]}]}) == [2]


def test_the_canonical_glb_keeps_each_meshs_other_keys_and_a_mesh_without_primitives():
    import json
    import struct

    doc = {"meshes": [{"name": "a", "weights": [0.5], "primitives": [{"mode": 4}]}, {"name": "b"}]}
    glb = _canonical_glb(doc, [])
    json_length = struct.unpack_from("<I", glb, 12)[0]
    assert json.loads(glb[20 : 20 + json_length])["meshes"] == [
        {"name": "a", "weights": [0.5], "primitives": [{"mode": 4}]},
        {"name": "b", "primitives": []},
    ]


def test_a_gltf_accessor_after_one_without_a_view_is_still_measured():
    doc = _accessor_doc({"componentType": 5126, "type": "VEC3", "count": 2}, 23)
    doc["accessors"].insert(0, {"componentType": 5126, "type": "VEC3", "count": 5})  # no bufferView
    doc["accessors"].insert(1, {"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 0})
    assert _refusal(_check_views, doc, [b"\0" * 64]) == (
        "a glTF accessor declares 2 elements (24 bytes), more than its buffer view holds (23 bytes):"
        " the file is corrupt"
    )


def test_an_empty_glb_binary_chunk_right_after_unpadded_json_is_read():
    assert _split_glb(_glb_of((_J, b"{}"), (_B, b""))) == ({}, b"")  # its 8-byte header ends the file


def test_a_gltf_without_nodes_places_no_mesh():
    budget, calls = _recorder()
    _check_counts(
        {"accessors": [_pos(3)], "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}]}, budget
    )
    assert calls == [("vertices", 0, _SCENE), ("faces", 0, _SCENE)]


def test_a_gltf_of_points_only_is_refused_naming_gltf():
    import base64
    import json

    doc = json.loads(_tetra_gltf("data:;base64," + base64.b64encode(_tetra_bin()).decode()))
    doc["meshes"][0]["primitives"] = [{"attributes": {"POSITION": 0}, "mode": 0}]  # points
    assert _refusal(read_gltf, json.dumps(doc).encode(), Budget()) == (
        "the glTF file holds no triangle mesh (only points, lines or nothing)"
    )


def test_glb_header_fields_are_unsigned_in_messages():
    with pytest.raises(UnsupportedFormatError) as info:
        read_glb(_glb_of((_J, b"{}"), version=2**31), Budget())
    assert str(info.value) == "unsupported mesh format: glTF 2147483648.0 is not supported: export glTF 2.0"
    assert _refusal(read_glb, _glb_of((_J, b"{}"), extra=2**31), Budget()) == (
        f"the GLB header declares {2**31 + 22} bytes, but the file holds 22: it is corrupt"
    )


def test_a_glb_chunk_size_of_2_gib_runs_past_the_end():
    import struct

    data = b"glTF" + struct.pack("<II", 2, 24) + struct.pack("<II", 2**31, _J) + b"{}  "
    assert _refusal(read_glb, data, Budget()) == "a GLB chunk runs past the end of the file: it is truncated"


@pytest.mark.parametrize("text", [b'{"a": 1} ', b'{"a": 1}  ', b'{"a": 1}   '])
def test_glb_padding_after_a_json_chunk_of_any_length_is_skipped(text):
    import struct

    body = (
        struct.pack("<II", len(text), _J)
        + text
        + b" " * (-len(text) % 4)
        + struct.pack("<II", 3, _B)
        + b"xyz"
    )
    data = b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body
    assert _split_glb(data) == ({"a": 1}, b"xyz")


@pytest.mark.parametrize(
    ("members", "message"),
    [
        (
            {"__MACOSX/a.gltf": b"{}", "b.txt": b""},
            "the .zip holds no .gltf or .glb file (a .zip upload is a glTF with its files)",
        ),
        ({"a.gltf": _tetra_gltf("bin/"), "bin/": b""}, "the glTF refers to 'bin/', which is not in the .zip"),
        ({"a.gltf": b'{"meshes": []}'}, "the glTF file holds no triangle mesh (it has no meshes)"),
    ],
)
def test_zip_mac_folders_and_folder_entries_are_not_files(members, message):
    assert _refusal(read_zip, _zip(members), Budget()) == message


# --- glTF in a .zip: the archive named as a zip, folders never read as files ---------------------------


def _damaged(members: dict[str, bytes], name: str) -> bytes:
    """A deflated archive of `members` whose member `name` does not unpack (the first bytes of its
    stream overwritten); the others are intact."""
    import struct

    data = bytearray(_zip(members, zipfile.ZIP_DEFLATED))
    at = zipfile.ZipFile(io.BytesIO(bytes(data))).getinfo(name).header_offset
    name_length, extra_length = struct.unpack_from("<HH", data, at + 26)
    start = at + 30 + name_length + extra_length
    data[start : start + 8] = b"\xff" * 8
    return bytes(data)


def test_a_zip_upload_that_is_no_zip_is_refused_as_a_zip():
    message = _refusal(read_zip, b"PK\x03\x04 but not an archive", Budget())
    assert message == "could not read the file as zip: it is not a valid zip archive"


@pytest.mark.parametrize("damaged", ["m/a.gltf", "m/t.bin"])
def test_a_zip_member_that_does_not_unpack_is_named_with_the_zip_archive(damaged):
    """The model and the file it refers to are unpacked as members of the zip archive, and a damaged
    one is named in words (not zlib's)."""
    members = {"m/a.gltf": _tetra_gltf("t.bin"), "m/t.bin": _tetra_bin()}
    assert len(read_zip(_zip(members, zipfile.ZIP_DEFLATED), Budget())[1]) == 4  # intact: read
    message = _refusal(read_zip, _damaged(members, damaged), Budget())
    assert message == f"could not unpack '{damaged}' from the zip archive: it is corrupt"


def test_a_folder_entry_is_never_read_as_a_file_the_gltf_names():
    """A uri resolving to "/" names the archive's root folder entry "/" exactly (normpath keeps a lone
    slash): it is a folder, so the file is missing, not read as empty bytes."""
    data = _zip({"a.gltf": _tetra_gltf("/"), "/": b""})
    assert "/" in zipfile.ZipFile(io.BytesIO(data)).namelist()
    assert _refusal(read_zip, data, Budget()) == "the glTF refers to '/', which is not in the .zip"


def _glb(doc: dict, chunk: bytes | None = None) -> bytes:
    import json
    import struct

    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), _J) + text
    if chunk is not None:
        body += struct.pack("<II", len(chunk), _B) + chunk
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def test_a_glb_in_a_zip_reads_the_files_it_refers_to_and_is_named_glb():
    """A GLB's buffer may live in a file beside it: read from the .zip, relative to the GLB. Its
    refusals name it GLB."""
    import json

    doc = json.loads(_tetra_gltf("t.bin"))
    vertices, faces = read_zip(_zip({"x/model.glb": _glb(doc), "x/t.bin": _tetra_bin()}), Budget())
    assert len(vertices) == 4 and len(faces) == 4
    del doc["buffers"][0]["uri"]  # and no binary chunk: nowhere to read it from
    message = _refusal(read_zip, _zip({"model.glb": _glb(doc)}), Budget())
    assert message == "the GLB buffer 0 has no data (no URI and no binary chunk)"


# --- STL's windows: the ASCII sniff reads the first KiB, the 'endsolid' check the last 4 KiB ---------------


@pytest.mark.parametrize(("blanks", "ascii"), [(1019, True), (1020, False)])
def test_an_stl_is_taken_for_ascii_only_when_solid_begins_within_its_first_kib(blanks, ascii):
    """'solid' ending at byte 1024 is seen; one byte later it is past the sniffed window, and the file is
    read as binary: its 'header' (blanks) declares 0x20202020 triangles, so it is refused as such."""
    data = b" " * blanks + _ascii_stl(_FACET)
    if ascii:
        assert read_stl(data, Budget())[1].tolist() == [[0, 1, 2]]
    else:
        assert _refusal(read_stl, data, Budget()).startswith("the STL header declares 538976288 triangles")


@pytest.mark.parametrize(("nul_at", "ascii"), [(1023, False), (1024, True)])
def test_a_nul_makes_an_stl_binary_only_within_its_first_kib(nul_at, ascii):
    """A NUL byte in the sniffed window marks a binary file that happens to start with 'solid' (some
    exporters write it in the header); past the window it is text the vertex lines never read."""
    name = b"solid " + b"n" * (nul_at - 6) + b"\x00\n"  # the solid's name line, its NUL at nul_at
    data = name + _FACET + b"endsolid t\n"
    assert data.index(b"\x00") == nul_at
    if ascii:
        assert read_stl(data, Budget())[1].tolist() == [[0, 1, 2]]
    else:
        assert _refusal(read_stl, data, Budget()).startswith("the STL header declares")


@pytest.mark.parametrize(("tail", "whole"), [(4096, True), (4097, False)])
def test_an_ascii_stl_is_cut_when_no_endsolid_begins_in_its_last_4_kib(tail, whole):
    """A second solid whose facets are not followed by 'endsolid' was cut; the check looks for
    'endsolid' in the last 4096 bytes, so the first solid's 'endsolid' counts only if it starts there."""
    first = b"solid a\n" + _FACET + b"endsolid a\n"
    name_length = tail - len(b"endsolid a\n") - len(b"solid \n") - len(_FACET)
    data = first + b"solid " + b"b" * name_length + b"\n" + _FACET  # cut: no endsolid b
    assert len(data) - data.index(b"endsolid a") == tail
    if whole:
        assert len(read_stl(data, Budget())[1]) == 2  # a cut between facets still parses (stl.py)
    else:
        message = _refusal(read_stl, data, Budget())
        assert message == "the ASCII STL does not end with 'endsolid': it is truncated"
