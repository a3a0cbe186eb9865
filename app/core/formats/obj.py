"""Wavefront OBJ: `v x y z [w | r g b]` vertices and `f a[/t][/n] ...` faces (polygons are fanned).

One regex pass and one C number parse per record kind: about 3x faster than trimesh's reader on large
files. Texture coordinates, normals, groups, materials, lines and points are ignored.
"""

from __future__ import annotations

import re

import numpy as np

from app.core.formats.common import fan_triangulate, first_columns, indices, numbers, text_lines
from app.core.meshdata import Budget, InvalidMeshError

_V = re.compile(rb"^[ \t]*v[ \t]+([^\n]*)", re.M)
_F = re.compile(rb"^[ \t]*f[ \t]+([^\n]*)", re.M)
_SLASH = re.compile(rb"/[^ \t]*")
_COMMENT = re.compile(rb"#[^\n]*")


def read_obj(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    """OBJ bytes -> vertices (n, 3) float64, faces (f, 3) int64 (0-based)."""
    text = text_lines(data).replace(b"\\\n", b" ")  # a trailing backslash continues the record
    if b"#" in text:
        text = _COMMENT.sub(b"", text)
    v_lines = _V.findall(text)
    if not v_lines:
        raise InvalidMeshError("the mesh has no vertices (the file has no OBJ 'v' lines)")
    budget.vertices(len(v_lines), "the OBJ file")
    f_lines = _F.findall(text)
    if not f_lines:
        raise InvalidMeshError(
            "the mesh has no faces (the OBJ file has no 'f' lines; a point cloud or lines are not a surface)"
        )
    values, widths = numbers(v_lines, "an OBJ vertex line")
    # each line has its own width: 'v x y z' and 'v x y z r g b' may be mixed in one file
    vertices = first_columns(values, widths, 3, "an OBJ vertex line")
    face_text = [_SLASH.sub(b"", line) if b"/" in line else line for line in f_lines]
    index, corners = indices(face_text, "an OBJ face line")
    if index.size and (index == 0).any():
        raise InvalidMeshError("an OBJ face refers to vertex 0, but OBJ counts vertices from 1")
    budget.faces(int((corners - 2).clip(min=1).sum()), "the OBJ file")
    if index.size and index.min() < 0:  # relative: -1 is the last vertex defined before this face
        before = _vertices_before_each_face(text)
        line = np.repeat(np.arange(corners.size), corners)
        negative = index < 0
        index[negative] += before[line[negative]] + 1
    return vertices, fan_triangulate(index - 1, corners)


def _vertices_before_each_face(text: bytes) -> np.ndarray:
    """(f,) int64 number of 'v' lines before each 'f' line."""
    v_at = np.fromiter((m.start() for m in _V.finditer(text)), dtype=np.int64)
    f_at = np.fromiter((m.start() for m in _F.finditer(text)), dtype=np.int64)
    return np.searchsorted(v_at, f_at).astype(np.int64)
