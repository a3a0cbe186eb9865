"""STL, binary (80-byte header, triangle count, 50 bytes per triangle) or ASCII (`vertex x y z`).

A binary file whose size disagrees with its declared triangle count is refused with both numbers,
never read in part. STL repeats each corner in every triangle: the welding in cleaning.py joins them.
"""

from __future__ import annotations

import re

import numpy as np

from app.core.formats.common import numbers, text_lines
from app.core.meshdata import Budget, InvalidMeshError

_RECORD = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])  # 50 bytes
_VERTEX = re.compile(rb"^[ \t]*vertex[ \t]+([^\n]*)", re.M | re.I)


def read_stl(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    """STL bytes -> vertices (3t, 3) float64 (three per triangle), faces (t, 3) int64."""
    if len(data) >= 84:
        count = int(np.frombuffer(data, "<u4", 1, 80)[0])
        if 84 + 50 * count == len(data):
            budget.faces(count, "the STL header")
            corners = np.frombuffer(data, _RECORD, count, 84)["corners"].reshape(-1, 3)
            with np.errstate(invalid="ignore"):  # a NaN pattern casts with a warning; validate names it
                vertices = corners.astype(np.float64)
            return vertices, np.arange(3 * count, dtype=np.int64).reshape(-1, 3)
        if not _looks_ascii(data):
            raise InvalidMeshError(
                f"the STL header declares {count} triangles ({84 + 50 * count} bytes), but the file holds"
                f" {len(data)} bytes: it is truncated or corrupt"
            )
    elif not _looks_ascii(data):
        raise InvalidMeshError("could not read the file as STL: it is too short for a binary STL")
    vertices, faces = _read_ascii(data, budget)
    if len(faces) == 0 and len(data) >= 84:
        raise InvalidMeshError(
            f"the file is neither an ASCII STL (no 'vertex' lines) nor a binary STL (its header declares"
            f" {count} triangles, {84 + 50 * count} bytes, but the file holds {len(data)} bytes)"
        )
    if len(faces) == 0:
        raise InvalidMeshError("the mesh has no vertices (the ASCII STL has no 'vertex' lines)")
    return vertices, faces


def _looks_ascii(data: bytes) -> bool:
    head = data[:1024].lstrip().lower()
    return head.startswith(b"solid") and b"\x00" not in data[:1024]


def _read_ascii(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    text = text_lines(data)
    lines = _VERTEX.findall(text)
    if lines and b"endsolid" not in text[-4096:].lower():  # a cut between two facets still parses
        raise InvalidMeshError("the ASCII STL does not end with 'endsolid': it is truncated")
    budget.faces(len(lines) // 3, "the STL file")
    if not lines:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    values, widths = numbers(lines, "an STL vertex line")
    if (widths != 3).any():
        raise InvalidMeshError("an STL vertex line does not hold exactly 3 numbers")
    if len(lines) % 3:
        raise InvalidMeshError(
            f"the ASCII STL holds {len(lines)} vertex lines, not 3 per facet: it is truncated"
        )
    return values.reshape(-1, 3), np.arange(len(lines), dtype=np.int64).reshape(-1, 3)
