"""Readers: every format loads a real file of its kind; unsupported formats say what to convert to."""

from __future__ import annotations

import base64
import io
import json
import re
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest
import trimesh

from app.core.cleaning import face_components
from app.core.mesh import (
    SUPPORTED_FORMATS,
    InvalidMeshError,
    UnsupportedFormatError,
    detect_format,
    load_mesh,
)

REALWORLD = Path(__file__).resolve().parents[3] / "shared" / "datasets" / "realworld"
needs_realworld = pytest.mark.skipif(not REALWORLD.is_dir(), reason=f"realworld corpus absent at {REALWORLD}")
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
