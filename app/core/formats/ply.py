"""PLY (ASCII, binary little- and big-endian): vertex x, y, z and the face index lists.

Faces of any size (triangles and quads mixed, in any encoding) are fanned into triangles. Declared
element counts are checked against the budget and against the bytes present before anything is read.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from app.core.formats.common import fan_triangulate, numbers, text_lines, whole_numbers
from app.core.meshdata import Budget, InvalidMeshError

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_FACE_LISTS = ("vertex_indices", "vertex_index")


@dataclass
class _Property:
    name: str
    dtype: str  # the item type
    count_dtype: str | None = None  # a list property: the type of its length prefix


@dataclass
class _Element:
    name: str
    count: int
    properties: list[_Property] = field(default_factory=list)


def read_ply(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    """PLY bytes -> vertices (n, 3) float64, faces (f, 3) int64."""
    encoding, elements, body = _header(data)
    for element in elements:
        if element.name == "vertex":
            budget.vertices(element.count, "the PLY header")
        elif element.name == "face":
            budget.faces(element.count, "the PLY header")
        elif element.count > 64 * max(1, len(data)):
            raise InvalidMeshError(
                f"the PLY header declares {element.count} '{element.name}' elements: corrupt"
            )
    names = [e.name for e in elements]
    if "vertex" not in names:
        raise InvalidMeshError("the mesh has no vertices (the PLY file has no 'vertex' element)")
    if "face" not in names or next(e for e in elements if e.name == "face").count == 0:
        raise InvalidMeshError("the mesh has no faces (a point cloud is not a surface)")
    if encoding == "ascii":
        return _read_ascii(text_lines(data[body:]), elements)
    return _read_binary(data, body, elements, "<" if encoding == "binary_little_endian" else ">")


def _header(data: bytes) -> tuple[str, list[_Element], int]:
    """-> (encoding, elements, offset of the body)."""
    if not text_lines(data[:8]).startswith(b"ply\n"):
        raise InvalidMeshError("could not read the file as PLY: it does not start with 'ply'")
    end = data.find(b"end_header")
    if end < 0 or end > 1 << 20:
        raise InvalidMeshError("could not read the file as PLY: the header has no 'end_header'")
    body = data.find(b"\n", end) + 1
    if body == 0:
        body = len(data)
    encoding = ""
    elements: list[_Element] = []
    for raw in text_lines(data[:end]).split(b"\n")[1:]:
        words = raw.decode("ascii", "replace").split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                encoding = words[1]
            elif words[0] == "element":
                elements.append(_Element(words[1], int(words[2])))
            elif words[0] == "property" and words[1] == "list":
                elements[-1].properties.append(_Property(words[4], _TYPES[words[3]], _TYPES[words[2]]))
            elif words[0] == "property":
                elements[-1].properties.append(_Property(words[2], _TYPES[words[1]]))
        except (IndexError, KeyError, ValueError):
            line = raw[:60].decode("ascii", "replace")
            raise InvalidMeshError(f"could not read the file as PLY: bad header line '{line}'") from None
    if encoding not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise InvalidMeshError(f"could not read the file as PLY: unknown format {encoding[:30]!r}")
    return encoding, elements, body


def _xyz(element: _Element) -> list[int]:
    names = [p.name for p in element.properties]
    if not all(axis in names for axis in "xyz") or any(p.count_dtype for p in element.properties):
        raise InvalidMeshError("the PLY vertex element has no x, y, z properties")
    return [names.index(axis) for axis in "xyz"]


def _face_list(element: _Element) -> int:
    lists = [i for i, p in enumerate(element.properties) if p.count_dtype is not None]
    named = [i for i in lists if element.properties[i].name in _FACE_LISTS]
    if not lists:
        raise InvalidMeshError("the PLY face element has no vertex index list")
    return (named or lists)[0]


def _read_ascii(text: bytes, elements: list[_Element]) -> tuple[np.ndarray, np.ndarray]:
    lines = [line for line in text.split(b"\n") if line.strip()]
    declared = sum(e.count for e in elements)
    if len(lines) != declared:
        state = "it is truncated" if len(lines) < declared else "the counts are wrong"
        raise InvalidMeshError(
            f"the PLY header declares {declared} element lines, but the file holds {len(lines)}: {state}"
        )
    vertices = faces = None
    at = 0
    for element in elements:
        block = lines[at : at + element.count]
        at += element.count
        if element.name == "vertex":
            values, widths = numbers(block, "a PLY vertex line")
            if (widths != len(element.properties)).any():
                raise InvalidMeshError("a PLY vertex line does not hold one number per property")
            vertices = values.reshape(-1, len(element.properties))[:, _xyz(element)]
        elif element.name == "face":
            faces = _ascii_faces(block, element)
    assert vertices is not None and faces is not None
    return vertices, faces


def _ascii_faces(block: list[bytes], element: _Element) -> np.ndarray:
    """Face lines -> (t, 3) fanned triangles; only scalar properties may precede the index list."""
    target = _face_list(element)
    if any(p.count_dtype for p in element.properties[:target]):
        raise InvalidMeshError("this PLY face layout (a list before the index list) is not supported")
    values, widths = numbers(block, "a PLY face line")
    starts = np.cumsum(widths) - widths + target
    if (widths <= target).any():
        raise InvalidMeshError("a PLY face line is shorter than its properties")
    k = whole_numbers(values[starts], "a PLY face corner count")
    if (widths < target + k + 1).any() or k.min() < 3:
        raise InvalidMeshError("a PLY face line lists fewer corners than its count says (at least 3)")
    corners = np.repeat(starts + 1, k) + np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
    return fan_triangulate(whole_numbers(values[corners], "a PLY face index"), k)


def _read_binary(
    data: bytes, at: int, elements: list[_Element], endian: str
) -> tuple[np.ndarray, np.ndarray]:
    vertices = faces = None
    for element in elements:
        if not any(p.count_dtype for p in element.properties):
            record = np.dtype([(f"p{i}", endian + p.dtype) for i, p in enumerate(element.properties)])
            if at + record.itemsize * element.count > len(data):
                raise _truncated(element, len(data) - at)
            table = np.frombuffer(data, record, element.count, at)
            at += record.itemsize * element.count
            if element.name == "vertex":
                vertices = np.stack([table[f"p{i}"] for i in _xyz(element)], axis=1).astype(np.float64)
            continue
        if element.name != "face":  # texture lists and the like: skip over them
            at = _walk(data, at, element, endian, -1)[2]
            continue
        faces, at = _binary_faces(data, at, element, endian)
    if len(data) - at > 64:  # a few bytes of padding are common; more means the counts lie
        raise InvalidMeshError(f"the PLY file holds {len(data) - at} bytes more than its header declares")
    assert vertices is not None and faces is not None
    return vertices, faces


def _truncated(element: _Element, left: int) -> InvalidMeshError:
    return InvalidMeshError(
        f"the PLY header declares {element.count} '{element.name}' elements, but only {max(left, 0)}"
        " bytes are left for them: the file is truncated"
    )


def _binary_faces(data: bytes, at: int, element: _Element, endian: str) -> tuple[np.ndarray, int]:
    """Face records of any width; -> ((t, 3) triangles, offset after the element)."""
    target = _face_list(element)
    props = element.properties
    n = element.count
    minimum = sum(np.dtype(p.count_dtype or p.dtype).itemsize for p in props)  # every list empty
    if at + n * minimum > len(data):
        raise _truncated(element, len(data) - at)
    uniform = _uniform_faces(data, at, element, endian, target)
    if uniform is not None:
        return uniform
    k, where, end = _walk(data, at, element, endian, target)
    if n and k.min() < 3:
        raise InvalidMeshError("a PLY face has fewer than 3 corners")
    item = np.dtype(props[target].dtype).itemsize
    pos = np.repeat(where, k) + (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) * item
    buf = np.frombuffer(data, np.uint8)
    raw = buf[pos[:, None] + np.arange(item)].copy().view(endian + props[target].dtype).ravel()
    return fan_triangulate(raw.astype(np.int64), k), end


def _uniform_faces(
    data: bytes, at: int, element: _Element, endian: str, target: int
) -> tuple[np.ndarray, int] | None:
    """The common case, every record shaped like the first (all triangles): one vectorised read."""
    first, _, _ = _walk(data, at, _Element(element.name, 1, element.properties), endian, target, lists=True)
    fields: list[tuple] = []
    for i, (p, c) in enumerate(zip(element.properties, first, strict=True)):
        if p.count_dtype is None:
            fields.append((f"p{i}", endian + p.dtype))
        else:
            fields += [(f"c{i}", endian + p.count_dtype), (f"p{i}", endian + p.dtype, (int(c),))]
    record = np.dtype(fields)
    if at + record.itemsize * element.count > len(data):
        return None
    table = np.frombuffer(data, record, element.count, at)
    for i, (p, c) in enumerate(zip(element.properties, first, strict=True)):
        if p.count_dtype is not None and (table[f"c{i}"] != c).any():
            return None
    k = int(first[target])
    if k < 3:
        raise InvalidMeshError("a PLY face has fewer than 3 corners")
    index = table[f"p{target}"].astype(np.int64).ravel()
    return fan_triangulate(
        index, np.full(element.count, k, dtype=np.int64)
    ), at + record.itemsize * element.count


def _walk(
    data: bytes, at: int, element: _Element, endian: str, target: int, lists: bool = False
) -> tuple[np.ndarray, np.ndarray, int]:
    """Walk variable-sized records once, reading only the list lengths.

    -> (k (n,) corners of each face, where (n,) byte offset of its first index, offset after the element);
    with lists=True (one record), k holds the length of every property instead (0 for scalars).
    """
    props = element.properties
    sizes = [np.dtype(p.dtype).itemsize for p in props]
    prefix = [struct.Struct(endian + np.dtype(p.count_dtype).char) if p.count_dtype else None for p in props]
    n, end = element.count, len(data)
    k = np.zeros(len(props) if lists else (n if target >= 0 else 0), dtype=np.int64)
    where = np.zeros(n if target >= 0 else 0, dtype=np.int64)
    offset = at
    try:
        for i in range(n):
            for j, counter in enumerate(prefix):
                if counter is None:
                    offset += sizes[j]
                    continue
                (c,) = counter.unpack_from(data, offset)
                offset += counter.size
                if lists:
                    k[j] = c
                elif j == target:
                    k[i], where[i] = c, offset
                offset += c * sizes[j]
            if offset > end:
                raise _truncated(element, end - at)
    except struct.error:
        raise _truncated(element, end - at) from None
    return k, where, offset
