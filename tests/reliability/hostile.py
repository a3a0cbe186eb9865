"""Hostile files of issue 34, generated in code (a few kilobytes each; no binary file is committed).

Each generator returns the bytes of one upload. Structure bombs declare or imply far more than they hold
(a 3MF component chain, a COLLADA instance_node DAG, a glTF with 100k nodes) and must be refused from
their declarations, fast; degenerate shapes must be answered or refused with words, never a 5xx.
"""

from __future__ import annotations

import io
import json
import struct
import zipfile

import numpy as np

from tests.reliability.corpus import obj_text

TETRA_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def identical_tetrahedra(n: int) -> bytes:
    """OBJ: n copies of one tetrahedron at the same place (4n vertices that weld to 4)."""
    return obj_text(np.tile(TETRA_V, (n, 1)), np.concatenate([TETRA_F + 4 * i for i in range(n)]))


def ribbon(n: int, width: float) -> bytes:
    """OBJ: a strip one triangle wide, n triangles long (vertices zig-zag between y=0 and y=width)."""
    x = np.arange(n + 2, dtype=float)
    v = np.c_[x, (np.arange(n + 2) % 2) * width, np.zeros(n + 2)]
    return obj_text(v, np.array([[i, i + 1, i + 2] for i in range(n)]))


# --- 3MF -------------------------------------------------------------------------------------------

_3MF_NS = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
_RELS = (
    '<?xml version="1.0" encoding="UTF-8"?><Relationships xmlns="http://schemas.openxmlformats.org/package/'
    '2006/relationships"><Relationship Target="/3D/3dmodel.model" Id="rel0" Type="http://schemas.microsoft.'
    'com/3dmanufacturing/2013/01/3dmodel"/></Relationships>'
)


def _tetra_3mf_mesh() -> str:
    vertices = "".join(f'<vertex x="{x}" y="{y}" z="{z}"/>' for x, y, z in TETRA_V.tolist())
    triangles = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in TETRA_F.tolist())
    return f"<mesh><vertices>{vertices}</vertices><triangles>{triangles}</triangles></mesh>"


def zip_members(members: dict[str, bytes | str]) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for name, content in members.items():
            z.writestr(name, content)
    return out.getvalue()


def threemf(objects: list[str], build: str) -> bytes:
    model = (
        f'<?xml version="1.0" encoding="UTF-8"?><model unit="millimeter" xmlns="{_3MF_NS}">'
        f"<resources>{''.join(objects)}</resources><build>{build}</build></model>"
    )
    return zip_members({"_rels/.rels": _RELS, "3D/3dmodel.model": model})


def component_chain_3mf(levels: int, copies: int) -> bytes:
    """Object 1 is a tetrahedron; object k places `copies` shifted copies of object k-1; the build places
    the last: copies**(levels-1) tetrahedra from a few KB."""
    objects = [f'<object id="1" type="model">{_tetra_3mf_mesh()}</object>']
    for k in range(2, levels + 1):
        parts = "".join(
            f'<component objectid="{k - 1}" transform="1 0 0 0 1 0 0 0 1 {2.0 * c} 0 0"/>'
            for c in range(copies)
        )
        objects.append(f'<object id="{k}" type="model"><components>{parts}</components></object>')
    return threemf(objects, f'<item objectid="{levels}"/>')


def component_cycle_3mf() -> bytes:
    objects = [
        f'<object id="1" type="model">{_tetra_3mf_mesh()}</object>',
        '<object id="2" type="model"><components><component objectid="3"/><component objectid="1"/>'
        "</components></object>",
        '<object id="3" type="model"><components><component objectid="2"/></components></object>',
    ]
    return threemf(objects, '<item objectid="2"/>')


def two_tetrahedra_3mf() -> bytes:
    """A valid 3MF: object 2 places object 1 twice, 3 apart along x, and the build places object 2 once,
    moved by +10 along z."""
    objects = [
        f'<object id="1" type="model">{_tetra_3mf_mesh()}</object>',
        '<object id="2" type="model"><components><component objectid="1"/>'
        '<component objectid="1" transform="1 0 0 0 1 0 0 0 1 3 0 0"/></components></object>',
    ]
    return threemf(objects, '<item objectid="2" transform="1 0 0 0 1 0 0 0 1 0 0 10"/>')


# --- COLLADA ---------------------------------------------------------------------------------------


def collada(library_nodes: str, scene_nodes: str) -> bytes:
    """A COLLADA 1.4 document with one tetrahedron geometry 'tet', the given library nodes and the
    visual scene's top nodes."""
    positions = " ".join(str(float(x)) for x in TETRA_V.ravel())
    p = " ".join(str(int(i)) for i in TETRA_F.ravel())
    return (
        '<?xml version="1.0" encoding="utf-8"?>'
        '<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">'
        '<asset><unit meter="1"/><up_axis>Z_UP</up_axis></asset>'
        '<library_geometries><geometry id="tet"><mesh>'
        f'<source id="tet-pos"><float_array id="tet-arr" count="12">{positions}</float_array>'
        '<technique_common><accessor source="#tet-arr" count="4" stride="3"><param name="X" type="float"/>'
        '<param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>'
        '<vertices id="tet-v"><input semantic="POSITION" source="#tet-pos"/></vertices>'
        f'<triangles count="4"><input semantic="VERTEX" source="#tet-v" offset="0"/><p>{p}</p></triangles>'
        "</mesh></geometry></library_geometries>"
        f"<library_nodes>{library_nodes}</library_nodes>"
        f'<library_visual_scenes><visual_scene id="scene">{scene_nodes}</visual_scene>'
        "</library_visual_scenes>"
        '<scene><instance_visual_scene url="#scene"/></scene></COLLADA>'
    ).encode()


def instance_node_dae(levels: int, copies: int) -> bytes:
    """Library node n0 places the tetrahedron; node nk places n(k-1) `copies` times."""
    nodes = ['<node id="n0"><instance_geometry url="#tet"/></node>']
    for k in range(1, levels):
        nodes.append(f'<node id="n{k}">' + f'<instance_node url="#n{k - 1}"/>' * copies + "</node>")
    return collada("".join(nodes), f'<node id="top"><instance_node url="#n{levels - 1}"/></node>')


def instance_node_cycle_dae() -> bytes:
    nodes = (
        '<node id="a"><instance_geometry url="#tet"/><instance_node url="#b"/></node>'
        '<node id="b"><instance_node url="#a"/></node>'
    )
    return collada(nodes, '<node id="top"><instance_node url="#a"/></node>')


def tetrahedron_dae() -> bytes:
    return collada("", '<node id="top"><instance_geometry url="#tet"/></node>')


# --- zips under other names ------------------------------------------------------------------------


def patched_zip(
    members: dict[str, bytes | str],
    *,
    version: int | None = None,
    method: int | None = None,
    declared_size: int | None = None,
) -> bytes:
    """A zip whose headers claim another 'version needed to extract', compression method or unpacked
    size than the data has (what a hostile or broken archiver writes)."""
    data = bytearray(zip_members(members))
    for sig, v_at, m_at, size_at in ((b"PK\x03\x04", 4, 8, 22), (b"PK\x01\x02", 6, 10, 24)):
        at = data.find(sig)
        while at >= 0:
            if version is not None:
                struct.pack_into("<H", data, at + v_at, version)
            if method is not None:
                struct.pack_into("<H", data, at + m_at, method)
            if declared_size is not None:
                struct.pack_into("<I", data, at + size_at, declared_size)
            at = data.find(sig, at + 4)
    return bytes(data)


# --- glTF ------------------------------------------------------------------------------------------


def glb(doc: dict | str, binary: bytes = b"") -> bytes:
    """A GLB from a JSON document (a dict, or JSON text that may hold what json.dumps never writes)."""
    text = (doc if isinstance(doc, str) else json.dumps(doc)).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if binary:
        chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


def _tetra_gltf(
    index_type: int = 5125, nodes: list | None = None, meshes: list | None = None
) -> tuple[dict, bytes]:
    positions = TETRA_V.astype("<f4").tobytes()
    index = TETRA_F.astype("<f4" if index_type == 5126 else "<u4").tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": nodes or [{"mesh": 0}],
        "meshes": meshes or [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(positions) + len(index)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(positions)},
            {"buffer": 0, "byteOffset": len(positions), "byteLength": len(index)},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": 4,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [1, 1, 1],
            },
            {"bufferView": 1, "componentType": index_type, "count": 12, "type": "SCALAR"},
        ],
    }
    return doc, positions + index


def tetrahedron_glb() -> bytes:
    return glb(*_tetra_gltf())


def float_index_glb() -> bytes:
    return glb(*_tetra_gltf(index_type=5126))


def huge_count_glb() -> bytes:
    """The index accessor's count is the JSON number 1e999 (infinity to a JSON reader)."""
    doc, binary = _tetra_gltf()
    return glb(json.dumps(doc).replace('"count": 12', '"count": 1e999'), binary)


def shared_children_glb(levels: int) -> bytes:
    """Each node has the next one as its child twice: 2**levels placements of one tetrahedron."""
    nodes: list[dict] = [{"children": [i + 1, i + 1]} for i in range(levels)] + [{"mesh": 0}]
    return glb(*_tetra_gltf(nodes=nodes))


def zipped_gltf(doc: dict, binary: bytes) -> bytes:
    """A .zip holding model.gltf and its model.bin: deflate packs a repetitive JSON 1000 to 1."""
    doc = dict(doc, buffers=[{"uri": "model.bin", "byteLength": len(binary)}])
    return zip_members({"model.gltf": json.dumps(doc, separators=(",", ":")), "model.bin": binary})


def many_nodes_zip(n: int) -> bytes:
    doc, binary = _tetra_gltf()
    return zipped_gltf(dict(doc, nodes=[{"mesh": 0}] + [{}] * (n - 1)), binary)


def many_primitives_zip(n: int) -> bytes:
    doc, binary = _tetra_gltf(meshes=[{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}] * n}])
    return zipped_gltf(doc, binary)


# --- XML entities ------------------------------------------------------------------------------------


def _laughs(root: str) -> str:
    """A DOCTYPE whose entity j expands to 10**9 'a's, and an external entity naming /etc/passwd."""
    chain = "".join(f'<!ENTITY {chr(98 + i)} "' + f"&{chr(97 + i)};" * 10 + '">' for i in range(9))
    return f'<?xml version="1.0"?><!DOCTYPE {root} [<!ENTITY a "aaaaaaaaaa">{chain}<!ENTITY x SYSTEM "file:///etc/passwd">]>'


def billion_laughs_3mf() -> bytes:
    objects = [f'<object id="1" type="model" name="&j;&x;">{_tetra_3mf_mesh()}</object>']
    model = threemf(objects, '<item objectid="1"/>')
    with zipfile.ZipFile(io.BytesIO(model)) as z:
        text = (
            z.read("3D/3dmodel.model")
            .decode()
            .replace('<?xml version="1.0" encoding="UTF-8"?>', _laughs("model"))
        )
        return zip_members({"_rels/.rels": z.read("_rels/.rels"), "3D/3dmodel.model": text})


def billion_laughs_dae() -> bytes:
    text = tetrahedron_dae().decode().replace('<?xml version="1.0" encoding="utf-8"?>', _laughs("COLLADA"))
    return text.replace('<node id="top">', '<node id="top" name="&j;&x;">').encode()
