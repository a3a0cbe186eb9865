"""glTF 2.0 in its three shapes: a GLB, a self-contained .gltf (data: URIs), or a .zip holding a .gltf
(or .glb) and its files. Draco-compressed primitives (KHR_draco_mesh_compression) are decoded.

Every input is first brought to one canonical GLB in memory (one JSON, one binary buffer), checked, then
read by trimesh, which bakes the node transforms. The checks run on the JSON before any array exists:
declared accessor sizes must fit their buffers, and the vertex and face counts, multiplied by the
number of nodes that instance each mesh, must fit the budget.
"""

from __future__ import annotations

import base64
import binascii
import json
import posixpath
import struct
from collections.abc import Callable
from urllib.parse import unquote

import numpy as np

from app.core.formats import graph
from app.core.formats.containers import open_zip, read_member
from app.core.formats.scene import load_with_trimesh
from app.core.meshdata import Budget, InvalidMeshError, UnsupportedFormatError

_JSON, _BIN = 0x4E4F534A, 0x004E4942
_COMPONENT = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_MESHOPT = ("EXT_meshopt_compression", "KHR_meshopt_compression")
MAX_INSTANCES = 10**9  # a node's count of placements saturates here (the limits are far below)
_INDEX_TYPES = {5121: "UNSIGNED_BYTE", 5123: "UNSIGNED_SHORT", 5125: "UNSIGNED_INT"}
_NAMES = {5120: "BYTE", 5122: "SHORT", 5126: "FLOAT", **_INDEX_TYPES}
Files = Callable[[str], bytes]


def read_glb(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    doc, chunk = _split_glb(data)
    return _read(doc, chunk, None, "GLB", budget)


def read_gltf(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    return _read(_parse_json(data, "glTF"), None, None, "glTF", budget)


def read_zip(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    """A .zip holding one .gltf (with its .bin and textures, which are ignored) or one .glb."""
    archive = open_zip(data, budget, "zip")
    names = [n for n in archive.namelist() if not n.startswith("__MACOSX/") and not n.endswith("/")]
    models = [
        n
        for n in names
        if n.lower().endswith((".gltf", ".glb")) and not posixpath.basename(n).startswith("._")
    ]
    if not models:
        raise InvalidMeshError(
            "the .zip holds no .gltf or .glb file (a .zip upload is a glTF with its files)"
        )
    if len(models) > 1:
        raise InvalidMeshError(
            f"the .zip holds several models ({', '.join(models[:5])}): upload one per file"
        )
    base = posixpath.dirname(models[0])

    def files(uri: str) -> bytes:
        name = posixpath.normpath(posixpath.join(base, unquote(uri)))
        if name not in names:
            raise InvalidMeshError(f"the glTF refers to '{uri[:80]}', which is not in the .zip")
        return read_member(archive, name, "zip")

    content = read_member(archive, models[0], "zip")
    if models[0].lower().endswith(".glb"):
        doc, chunk = _split_glb(content)
        return _read(doc, chunk, files, "GLB", budget)
    return _read(_parse_json(content, "glTF"), None, files, "glTF", budget)


def _split_glb(data: bytes) -> tuple[dict, bytes | None]:
    """GLB bytes -> (JSON document, binary chunk or None)."""
    if len(data) < 20 or data[:4] != b"glTF":
        raise InvalidMeshError("could not read the file as GLB: it does not start with 'glTF'")
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise UnsupportedFormatError(
            f"unsupported mesh format: glTF {version}.0 is not supported: export glTF 2.0"
        )
    if length != len(data):
        raise InvalidMeshError(
            f"the GLB header declares {length} bytes, but the file holds {len(data)}: it is corrupt"
        )
    doc, chunk, at = None, None, 12
    while at + 8 <= len(data):
        size, kind = struct.unpack_from("<II", data, at)
        if at + 8 + size > len(data):
            raise InvalidMeshError("a GLB chunk runs past the end of the file: it is truncated")
        if kind == _JSON and doc is None:
            doc = _parse_json(data[at + 8 : at + 8 + size], "GLB")
        elif kind == _BIN and chunk is None:
            chunk = data[at + 8 : at + 8 + size]
        at += 8 + size
        if at % 4 and _chunk_type(data, at) not in (_JSON, _BIN):  # padding is required, yet some omit it
            at += -at % 4
    if doc is None:
        raise InvalidMeshError("could not read the file as GLB: it has no JSON chunk")
    return doc, chunk


def _chunk_type(data: bytes, at: int) -> int | None:
    return struct.unpack_from("<I", data, at + 4)[0] if at + 8 <= len(data) else None


def _parse_json(data: bytes, what: str) -> dict:
    try:
        doc = json.loads(data.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InvalidMeshError(f"could not read the file as {what}: its JSON is invalid") from exc
    if not isinstance(doc, dict):
        raise InvalidMeshError(f"could not read the file as {what}: its JSON is not an object")
    return doc


def _read(
    doc: dict, chunk: bytes | None, files: Files | None, what: str, budget: Budget
) -> tuple[np.ndarray, np.ndarray]:
    if not doc.get("meshes"):
        raise InvalidMeshError(f"the {what} file holds no triangle mesh (it has no meshes)")
    try:
        _check_extensions(doc)
        _check_declared(doc)
        buffers = _buffers(doc, chunk, files, what, budget)
        _check_views(doc, buffers)
        _check_counts(doc, budget)
        glb = _canonical_glb(doc, buffers)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        if isinstance(exc, InvalidMeshError):
            raise
        raise InvalidMeshError(f"could not read the file as {what}: its JSON structure is invalid") from exc
    return load_with_trimesh(glb, "glb", what, budget)


def _check_extensions(doc: dict) -> None:
    declared = set(doc.get("extensionsUsed", [])) | set(doc.get("extensionsRequired", []))
    for name in _MESHOPT:
        if name in declared:
            raise UnsupportedFormatError(
                f"unsupported mesh format: meshopt-compressed glTF ({name}) is not supported:"
                " export it without meshopt compression (Draco is fine), or as OBJ, PLY, STL, GLB or 3MF"
            )
    if "EXT_mesh_gpu_instancing" in doc.get("extensionsRequired", []):
        raise UnsupportedFormatError(
            "unsupported mesh format: GPU instancing (EXT_mesh_gpu_instancing) is not supported:"
            " apply the instances and export again"
        )


def _buffers(doc: dict, chunk: bytes | None, files: Files | None, what: str, budget: Budget) -> list[bytes]:
    out = []
    for i, buffer in enumerate(doc.get("buffers", [])):
        uri = buffer.get("uri")
        if uri is None:
            if i != 0 or chunk is None:
                raise InvalidMeshError(f"the {what} buffer {i} has no data (no URI and no binary chunk)")
            data = chunk
        elif uri.startswith("data:"):
            if len(uri) * 3 // 4 > budget.unpacked_bytes():
                raise InvalidMeshError(f"the {what} buffer {i} is larger than allowed")
            try:
                data = base64.b64decode(uri.split(",", 1)[1], validate=False)
            except (IndexError, binascii.Error) as exc:
                raise InvalidMeshError(f"the {what} buffer {i} has a malformed data: URI") from exc
        elif files is None:
            container = "a self-contained GLB" if what == "GLB" else "a self-contained .gltf or GLB"
            raise InvalidMeshError(
                f"the {what} refers to an external file '{uri[:80]}';"
                f" upload a .zip holding both, or {container}"
            )
        else:
            data = files(uri)
        if _n(buffer.get("byteLength", 0), "buffer byteLength") > len(data):
            raise InvalidMeshError(
                f"the {what} buffer {i} declares {buffer['byteLength']} bytes, but holds {len(data)}:"
                " it is truncated"
            )
        out.append(data)
    return out


def _n(value: object, what: str) -> int:
    """A JSON number that must be a whole number in range (a count, an index, an offset) -> int."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**53:
        raise InvalidMeshError(f"the glTF {what} is not a whole number in range: {str(value)[:30]}")
    return value


def _check_views(doc: dict, buffers: list[bytes]) -> None:
    """Every buffer view inside its buffer; every accessor inside its view."""
    views = doc.get("bufferViews", [])
    for view in views:
        start, length = _n(view.get("byteOffset", 0), "byteOffset"), _n(view["byteLength"], "byteLength")
        if start + length > len(buffers[_n(view["buffer"], "buffer index")]):
            raise InvalidMeshError("a glTF buffer view runs past the end of its buffer: the file is corrupt")
    for accessor in doc.get("accessors", []):
        count = _n(accessor["count"], "accessor count")
        if "bufferView" not in accessor or count == 0:
            continue
        kind = _n(accessor["componentType"], "accessor componentType")
        if kind not in _COMPONENT or accessor.get("type") not in _WIDTH:
            raise InvalidMeshError(
                f"a glTF accessor has an unknown type ({kind}, {str(accessor.get('type'))[:20]}): the file is"
                " corrupt"
            )
        view = views[_n(accessor["bufferView"], "bufferView index")]
        element = _COMPONENT[kind] * _WIDTH[accessor["type"]]
        stride = _n(view.get("byteStride", 0), "byteStride") or element
        need = _n(accessor.get("byteOffset", 0), "byteOffset") + stride * (count - 1) + element
        if need > _n(view["byteLength"], "byteLength"):
            raise InvalidMeshError(
                f"a glTF accessor declares {count} elements ({need} bytes), more than its buffer view holds"
                f" ({view['byteLength']} bytes): the file is corrupt"
            )


def _check_counts(doc: dict, budget: Budget) -> None:
    """Declared sizes before anything is built: nodes, accessors and primitives, their types, and the
    meshes, vertices and faces of the whole scene, each mesh counted once per node instance."""
    accessors = doc.get("accessors", [])
    _check_declared(doc)
    per_mesh = []
    for mesh in doc["meshes"]:
        total = graph.Totals()
        for primitive in mesh.get("primitives", []):
            total = total + _primitive(primitive, accessors)
        per_mesh.append(total)
    instances = _instances(doc)
    total = graph.Totals()
    for i, node in _mesh_nodes(doc):
        m = per_mesh[_n(node["mesh"], "mesh index")]
        total = total + graph.Totals(
            instances[i] * m.placements, instances[i] * m.vertices, instances[i] * m.faces
        )
    graph.check(total, "glTF scene", budget)


def _check_declared(doc: dict) -> None:
    """Nodes, accessors and primitives a document declares, before anything is read from its buffers."""
    graph.check_declared(len(doc.get("nodes", [])), "nodes", "glTF file")
    graph.check_declared(len(doc.get("accessors", [])), "accessors", "glTF file")
    graph.check_declared(sum(len(m.get("primitives", [])) for m in doc["meshes"]), "primitives", "glTF file")


def _primitive(primitive: dict, accessors: list) -> graph.Totals:
    """One primitive's declared vertices and faces; its POSITION and index accessors of the right types."""
    position = accessors[_n(primitive["attributes"]["POSITION"], "POSITION accessor index")]
    if position["type"] != "VEC3":
        raise InvalidMeshError(
            f"a glTF POSITION accessor is {str(position['type'])[:10]}, not VEC3: the file is corrupt"
        )
    n = _n(position["count"], "accessor count")
    if "indices" in primitive:
        index = accessors[_n(primitive["indices"], "indices accessor index")]
        kind = _n(index["componentType"], "accessor componentType")
        if kind not in _INDEX_TYPES or index["type"] != "SCALAR":
            raise InvalidMeshError(
                f"a glTF index accessor holds {_NAMES.get(kind, kind)} {str(index['type'])[:10]} values:"
                " indices must be unsigned integers (SCALAR UNSIGNED_BYTE, SHORT or INT); the file is corrupt"
            )
        n_index = _n(index["count"], "accessor count")
    else:
        n_index = n
    mode = _n(primitive.get("mode", 4), "primitive mode")
    faces = n_index // 3 if mode == 4 else max(n_index - 2, 0) if mode in (5, 6) else 0
    return graph.Totals(int(faces > 0), n, faces)


def _mesh_nodes(doc: dict) -> list[tuple[int, dict]]:
    return [(i, node) for i, node in enumerate(doc.get("nodes", [])) if "mesh" in node]


def _instances(doc: dict) -> list[int]:
    """(nodes,) how many times each node is placed: paths from the scene's roots (a tree: 0 or 1;
    a malformed file can share children and multiply them). A cycle is refused."""
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes", [])
    if scenes:
        roots = [_n(r, "node index") for r in scenes[_n(doc.get("scene", 0), "scene index")].get("nodes", [])]
    else:  # no scene: every node no one parents is a root
        children = {_n(c, "node index") for node in nodes for c in node.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    parents = [0] * len(nodes)
    for node in nodes:
        for c in node.get("children", []):
            parents[_n(c, "node index")] += 1
    count = [0] * len(nodes)
    for r in roots:
        count[r] += 1
    ready = [i for i in range(len(nodes)) if parents[i] == 0]
    done = 0
    while ready:  # Kahn's order: a node's count is final once all its parents are done
        i = ready.pop()
        done += 1
        for c in nodes[i].get("children", []):
            c = int(c)
            count[c] = min(count[c] + count[i], MAX_INSTANCES + 1)
            parents[c] -= 1
            if parents[c] == 0:
                ready.append(c)
    if done != len(nodes):
        raise InvalidMeshError("the glTF node hierarchy has a cycle: the file is corrupt")
    return count


def _canonical_glb(doc: dict, buffers: list[bytes]) -> bytes:
    """One JSON + one binary chunk: buffers concatenated (8-byte aligned), views re-pointed; materials,
    textures and images dropped (geometry only: a missing texture must not fail the shape)."""
    doc = dict(doc)
    starts, blob = [], bytearray()
    for data in buffers:
        blob += b"\0" * (-len(blob) % 8)
        starts.append(len(blob))
        blob += data
    views = []
    for view in doc.get("bufferViews", []):
        view = dict(view)
        view["byteOffset"] = starts[int(view["buffer"])] + int(view.get("byteOffset", 0))
        view["buffer"] = 0
        views.append(view)
    doc["bufferViews"] = views
    doc["buffers"] = [{"byteLength": len(blob)}] if blob else []
    for key in ("materials", "textures", "images", "samplers"):
        doc.pop(key, None)
    doc["meshes"] = [
        dict(
            mesh,
            primitives=[{k: v for k, v in p.items() if k != "material"} for p in mesh.get("primitives", [])],
        )
        for mesh in doc.get("meshes", [])
    ]
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<II", len(text), _JSON) + text
    if blob:
        chunks += struct.pack("<II", len(blob), _BIN) + bytes(blob)
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks
