"""A corpus of bad uploads, generated in code (no binary files are committed).

Each case is one multipart upload: a file name, its bytes, and optional form fields. Every case must be
refused with a 4xx and a message a user understands, by POST /models and by POST /search, and the store
must be unchanged afterwards. Cases marked `file_level` are bad in their content alone, so the CLI
(`shapebag search FILE`) must refuse them too (exit 2, one line).

`OVER_VERTEX_LIMIT` cases assume the server runs with max_vertices=MAX_VERTICES.
"""

from __future__ import annotations

import io
import json
import struct
from dataclasses import dataclass, field

import numpy as np
import trimesh

MAX_VERTICES = 3000  # the test settings' SHAPEBAG_MAX_VERTICES
FORMATS = ("obj", "off", "ply", "stl", "glb")


@dataclass(frozen=True)
class BadInput:
    case: str
    filename: str
    content: bytes
    fields: dict[str, str | bytes] = field(default_factory=dict)
    file_level: bool = True  # bad in its bytes (not only its name or form fields)

    def __repr__(self) -> str:  # short, for pytest ids and failure messages
        return f"BadInput({self.case}, {self.filename!r}, {len(self.content)} bytes)"


def _sphere(subdivisions: int = 2) -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=subdivisions)


def valid_bytes(file_type: str, mesh: trimesh.Trimesh | None = None) -> bytes:
    """A valid mesh file of `file_type` (binary PLY/STL, GLB)."""
    mesh = mesh if mesh is not None else _sphere()
    data = mesh.export(file_type=file_type)
    return data.encode() if isinstance(data, str) else bytes(data)


def obj_text(vertices: np.ndarray, faces: np.ndarray | None) -> bytes:
    """vertices (n, 3), faces (f, 3) 0-based -> OBJ text (faces written 1-based)."""
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, float).tolist()]
    if faces is not None:
        lines += ["f " + " ".join(str(int(i) + 1) for i in face) for face in faces]
    return ("\n".join(lines) + "\n").encode()


def _bad_obj_values(value: float) -> bytes:
    s = _sphere(1)
    v = s.vertices.copy()
    v[3, 1] = value
    return obj_text(v, s.faces)


def _triangle_soup(n: int = 600) -> bytes:
    """n disjoint triangles of equal area: no part has a surface (issue 10: a shape of many equal parts is
    kept, so equal tetrahedra are no longer refused as debris; a soup of lone triangles is)."""
    tri_v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float) * 1e-3
    verts = (tri_v[None] + np.arange(n)[:, None, None] * np.array([0.01, 0, 0])).reshape(-1, 3)
    return obj_text(verts, np.arange(3 * n).reshape(-1, 3))


def _fan(blades: int = 40) -> bytes:
    """`blades` triangles hinged on one edge (a book with no covers): every face meets at a
    non-manifold edge, and nothing else in the mesh connects them."""
    v = [[0, 0, 0], [0, 0, 1]]
    f = []
    for i in range(blades):
        a = 2 * np.pi * i / blades
        v.append([np.cos(a), np.sin(a), 0.5])
        f.append([0, 1, 2 + i])
    return obj_text(np.array(v), np.array(f))


def _glb_bomb() -> bytes:
    """A 300-byte GLB whose accessor claims 10^9 vertices (12 GB of floats) in a 36-byte buffer."""
    blob = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    gltf = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 4_000_000_000}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 1_000_000_000, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "mode": 4}]}],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    }
    js = json.dumps(gltf).encode()
    js += b" " * (-len(js) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(blob), 0x004E4942) + blob
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def _ply_header_bomb() -> bytes:
    """A binary PLY header that promises 2*10^9 vertices and faces, followed by a few bytes."""
    head = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\n"
        b"property float x\nproperty float y\nproperty float z\nelement face 2000000000\n"
        b"property list uchar int vertex_indices\nend_header\n"
    )
    return head + b"\x00" * 64


def _stl_count_bomb() -> bytes:
    """A binary STL whose header claims 4*10^9 triangles but holds one."""
    tri = struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
    return b"\0" * 80 + struct.pack("<I", 4_000_000_000) + tri


def _nan_stl() -> bytes:
    s = _sphere(1)
    v = s.vertices.copy()
    v[0] = np.nan
    return valid_bytes("stl", trimesh.Trimesh(v, s.faces, process=False))


def _over_limit() -> bytes:
    big = _sphere(5)  # 10,242 vertices > MAX_VERTICES
    assert len(big.vertices) > MAX_VERTICES
    return obj_text(big.vertices, big.faces)


def _png_bytes() -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (8, 8), (200, 10, 10)).save(buf, format="PNG")
    return buf.getvalue()


def build() -> list[BadInput]:
    """The whole corpus (deterministic: fixed seeds)."""
    rng = np.random.default_rng(20260601)
    cases: list[BadInput] = [BadInput("empty", "empty.obj", b"")]
    for ext in FORMATS:
        cases.append(BadInput(f"random-{ext}", f"noise.{ext}", rng.bytes(4096)))
    for ext, keep in (("obj", 0.3), ("off", 0.5), ("ply", 0.5), ("stl", 0.5), ("glb", 0.5), ("glb", 0.05)):
        data = valid_bytes(ext)
        cases.append(BadInput(f"truncated-{ext}-{keep}", f"cut.{ext}", data[: int(len(data) * keep)]))
    ascii_ply = _sphere().export(file_type="ply", encoding="ascii")
    ascii_ply = ascii_ply if isinstance(ascii_ply, bytes) else ascii_ply.encode()
    cases.append(BadInput("truncated-ply-ascii", "cut.ply", ascii_ply[: len(ascii_ply) // 2]))
    ascii_stl = trimesh.exchange.stl.export_stl_ascii(_sphere()).encode()
    cases.append(BadInput("truncated-stl-ascii", "cut.stl", ascii_stl[: len(ascii_stl) // 3]))
    s = _sphere(1)
    cases += [
        BadInput("nan-obj", "nan.obj", _bad_obj_values(float("nan"))),
        BadInput("inf-obj", "inf.obj", _bad_obj_values(float("inf"))),
        BadInput("huge-coord-obj", "huge.obj", _bad_obj_values(1e308).replace(b"1e+308", b"1e999")),
        BadInput("nan-stl", "nan.stl", _nan_stl()),
        BadInput("face-missing-vertex", "holes.obj", obj_text(s.vertices, s.faces) + b"f 1 2 999\n"),
        # on a whole mesh, so the refusal is the 0 (OBJ counts from 1) and not "too few vertices"
        *(
            BadInput(f"face-index-zero-{i}", "zero.obj", obj_text(s.vertices, s.faces) + face)
            for i, face in enumerate((b"f 0 1 2\n", b"f 1 0 2\n", b"f 3 4 0\n"))
        ),
        BadInput(
            "face-missing-vertex-off",
            "holes.off",
            b"OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 9\n",
        ),
        BadInput(
            "zero-area-collinear",
            "line.obj",
            obj_text(
                np.c_[np.arange(10.0), np.zeros(10), np.zeros(10)], [[i, i + 1, i + 2] for i in range(8)]
            ),
        ),
        BadInput(
            "zero-area-one-point", "dot.obj", obj_text(np.zeros((6, 3)), [[0, 1, 2], [3, 4, 5], [0, 2, 4]])
        ),
        BadInput("point-cloud-obj", "cloud.obj", obj_text(rng.normal(size=(200, 3)), None)),
        BadInput(
            "point-cloud-ply",
            "cloud.ply",
            trimesh.PointCloud(rng.normal(size=(200, 3))).export(file_type="ply"),
        ),
        BadInput("point-cloud-off", "cloud.off", b"OFF\n4 0 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"),
        BadInput("one-triangle", "tri.obj", obj_text(np.eye(3), [[0, 1, 2]])),
        BadInput("one-triangle-stl", "tri.stl", valid_bytes("stl", trimesh.Trimesh(np.eye(3), [[0, 1, 2]]))),
        BadInput(
            "two-triangles",
            "quad.obj",
            obj_text([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]]),
        ),
        BadInput("non-manifold-fan", "fan.obj", _fan()),
        BadInput("triangle-soup", "dust.obj", _triangle_soup()),
        BadInput("over-vertex-limit", "dense.obj", _over_limit()),
        BadInput("glb-accessor-bomb", "bomb.glb", _glb_bomb()),
        BadInput("ply-header-bomb", "bomb.ply", _ply_header_bomb()),
        BadInput("stl-count-bomb", "bomb.stl", _stl_count_bomb()),
        BadInput("gzip-as-obj", "packed.obj", _gzip_bomb(1 << 20)),
        BadInput("png-as-obj", "picture.obj", _png_bytes()),
        BadInput("obj-as-stl", "shape.stl", obj_text(s.vertices, s.faces)),
        BadInput("stl-as-obj", "shape.obj", valid_bytes("stl")),
        BadInput("glb-as-off", "shape.off", valid_bytes("glb")),
        BadInput("json-as-glb", "shape.glb", b'{"asset": {"version": "2.0"}}'),
        BadInput("html-as-ply", "shape.ply", b"<!doctype html><html><body>not a mesh</body></html>"),
        BadInput("no-extension", "shape", valid_bytes("obj")),
        BadInput("wrong-extension", "shape.exe", valid_bytes("obj")),
    ]
    good = valid_bytes("obj", _sphere(2).apply_scale(1.7))
    cases += [
        BadInput("path-traversal", "../../../../etc/cron.d/x.obj", good, file_level=False),
        BadInput("path-traversal-windows", "..\\..\\windows\\system32\\x.obj", good, file_level=False),
        BadInput("absolute-path", "/etc/passwd.obj", good, file_level=False),
        BadInput("nul-in-filename", "evil\x00.obj", good, file_level=False),
        BadInput("enormous-label", "ok.obj", good, {"label": "L" * 100_000}, file_level=False),
        BadInput("long-label", "ok.obj", good, {"label": "L" * 1000}, file_level=False),
        BadInput("bidi-override-label", "ok.obj", good, {"label": "chair\u202egpj.exe"}, file_level=False),
        BadInput("control-chars-name", "ok.obj", good, {"name": "a\x1b[31mred\x07"}, file_level=False),
        BadInput("nul-in-label", "ok.obj", good, {"label": "cat\x00dog"}, file_level=False),
        BadInput(
            "invalid-utf8-label", "ok.obj", good, {"label": b"caf\xe9 (latin-1, not UTF-8)"}, file_level=False
        ),
        BadInput("filename-256-chars", "n" * 252 + ".obj", good, file_level=False),
        BadInput("filename-1000-chars", "n" * 996 + ".obj", good, file_level=False),
    ]
    # one case per refused character class, in the file name, the name and the label
    odd = {
        "control": "\x07",
        "format-zwsp": "\u200b",
        "format-bom": "\ufeff",
        "private-use": "\ue000",
        "private-use-plane-15": "\U000f0001",
    }
    for what, ch in odd.items():
        cases += [
            BadInput(f"{what}-in-filename", f"a{ch}b.obj", good, file_level=False),
            BadInput(f"{what}-in-name", "ok.obj", good, {"name": f"a{ch}b"}, file_level=False),
            BadInput(f"{what}-in-label", "ok.obj", good, {"label": f"a{ch}b"}, file_level=False),
        ]
    return cases


def _gzip_bomb(size: int) -> bytes:
    """`size` bytes of OBJ-looking text gzip-compressed to ~1 kB (a .obj must be plain text)."""
    import gzip

    return gzip.compress(b"v 0 0 0\n" * (size // 8), compresslevel=9)


def gzip_body_bomb(size: int = 512 << 20) -> bytes:
    """A gzip stream that inflates to `size` zero bytes (~0.5 MB for 512 MB); sent as Content-Encoding."""
    import zlib

    comp = zlib.compressobj(9, zlib.DEFLATED, 31)  # gzip container
    chunk = b"\0" * (1 << 20)
    out = [comp.compress(chunk) for _ in range(size >> 20)]
    out.append(comp.flush())
    return b"".join(out)


def bad_metadata() -> list[tuple[str, str]]:
    """(case, raw `metadata` field) that standard JSON cannot round-trip or that pass the caps.

    Each class is generated over several variants (where it sits, how deep, how long), so a fix for
    only the tester's example would not pass.
    """
    cases: list[tuple[str, str]] = []
    for surrogate in ("\\ud800", "\\udfff", "\\udbff"):  # high, low, last high
        cases += [
            (f"surrogate-value-{surrogate[2:]}", f'{{"a": "x{surrogate}y"}}'),
            (f"surrogate-key-{surrogate[2:]}", f'{{"{surrogate}": 1}}'),
            (f"surrogate-nested-{surrogate[2:]}", f'{{"a": [{{"b": ["{surrogate}"]}}]}}'),
        ]
    for constant in ("NaN", "Infinity", "-Infinity", "1e999", "-1e400"):
        cases += [
            (f"nonfinite-{constant}", f'{{"a": {constant}}}'),
            (f"nonfinite-in-list-{constant}", f'{{"a": [1, {constant}]}}'),
        ]
    for depth in (17, 64, 255, 256, 1000, 100_000):
        cases += [
            (f"deep-objects-{depth}", '{"a": ' * depth + "1" + "}" * depth + "}"),
            (f"deep-arrays-{depth}", '{"a": ' + "[" * depth + "]" * depth + "}"),
        ]
    for digits in (20, 40, 4300, 5000):
        cases += [
            (f"big-int-{digits}", f'{{"a": {"9" * digits}}}'),
            (f"big-negative-int-{digits}", f'{{"a": -{"9" * digits}}}'),
        ]
    cases += [
        ("int-just-over-int64", f'{{"a": {2**63}}}'),
        ("duplicate-key", '{"a": 1, "a": 2}'),
        ("too-long", '{"a": "' + "x" * 20_000 + '"}'),
        ("not-an-object", "[1, 2]"),
        ("not-json", "{a: 1}"),
        ("trailing-garbage", '{"a": 1} x'),
    ]
    return cases


def good_metadata() -> list[str]:
    """Edge cases that are standard JSON within the caps: accepted, stored, served back unchanged."""
    nested = '{"a": ' * 15 + "1" + "}" * 15
    return [
        f'{{"max": {2**63 - 1}, "min": {-(2**63)}, "pi": 3.14159, "tiny": 1e-300}}',
        '{"text": "caf\\u00e9 \\ud83d\\ude00 \\u4e2d", "empty": "", "null": null, "list": [true, false]}',
        f'{{"deep": {nested}}}',
    ]


def duplicate_field_bodies(boundary: str, good: bytes) -> list[tuple[str, bytes]]:
    """(case, multipart body) where one field appears twice: each of file, name, label, metadata, k,
    twice in a row or apart, with the same or different values (the last must not silently win)."""

    def part(name: str, value: bytes, filename: str | None = None) -> bytes:
        disp = f'form-data; name="{name}"' + (f'; filename="{filename}"' if filename else "")
        return f"--{boundary}\r\nContent-Disposition: {disp}\r\n\r\n".encode() + value + b"\r\n"

    file_part = part("file", good, "a.obj")
    cases = [
        ("file-twice", file_part + part("file", good + b"\n", "b.obj")),
        ("file-twice-same", file_part + file_part),
        ("file-as-text-too", part("file", b"text") + file_part),
    ]
    for name, a, b in (
        ("name", b"a", b"b"),
        ("label", b"x", b"y"),
        ("metadata", b"{}", b'{"a": 1}'),
        ("k", b"3", b"4"),
    ):
        cases.append((f"{name}-twice", part(name, a) + part(name, b) + file_part))
        cases.append((f"{name}-apart", part(name, a) + file_part + part(name, a)))
    return [(case, body + f"--{boundary}--\r\n".encode()) for case, body in cases]
