"""Object File Format: `OFF` (or COFF, NOFF, CNOFF, STOFF...), counts, vertex lines, polygon lines.

The header's counts are checked against the budget and against the lines present: a truncated file or
one with more data than declared is refused, never half-read. Polygons are fanned into triangles.
"""

from __future__ import annotations

import re

import numpy as np

from app.core.formats.common import fan_triangulate, first_columns, numbers, text_lines, whole_numbers
from app.core.meshdata import Budget, InvalidMeshError

_COMMENT = re.compile(rb"#[^\n]*")
_KEYWORD = re.compile(rb"^(ST)?C?N?(4)?(n)?OFF(BINARY)?")


def read_off(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    """OFF bytes -> vertices (n, 3) float64, faces (f, 3) int64."""
    text = text_lines(data)
    if b"#" in text:
        text = _COMMENT.sub(b"", text)
    lines = [line for line in text.split(b"\n") if line.strip()]
    if not lines:
        raise InvalidMeshError("the mesh has no vertices (the OFF file is empty)")
    first = lines[0].strip()
    keyword = _KEYWORD.match(first)
    if keyword is None:
        raise InvalidMeshError("could not read the file as OFF: it does not start with 'OFF'")
    if keyword.group(2) or keyword.group(3) or keyword.group(4):
        raise InvalidMeshError(
            "this OFF variant (4D, n-dimensional or binary) is not supported: export plain OFF"
        )
    head = first[keyword.end() :].split()  # some writers glue the counts to the keyword: 'OFF8 6 12'
    counts_tokens, body = (
        (head, lines[1:]) if head else (lines[1].split() if len(lines) > 1 else [], lines[2:])
    )
    try:
        n_vertices, n_faces = int(counts_tokens[0]), int(counts_tokens[1])
    except (IndexError, ValueError):
        raise InvalidMeshError(
            "could not read the file as OFF: the counts line is missing or not numbers"
        ) from None
    budget.vertices(n_vertices, "the OFF header")
    budget.faces(n_faces, "the OFF header")
    declared = f"the OFF header declares {n_vertices} vertices and {n_faces} faces"
    if len(body) < n_vertices + n_faces:
        raise InvalidMeshError(f"{declared}, but the file holds only {len(body)} data lines: it is truncated")
    if len(body) > n_vertices + n_faces:
        raise InvalidMeshError(
            f"{declared}, but the file holds {len(body)} data lines:"
            " the counts are wrong or the file is corrupt"
        )
    values, widths = numbers(body[:n_vertices], "an OFF vertex line")
    vertices = first_columns(values, widths, 3, "an OFF vertex line")
    raw, widths = numbers(body[n_vertices:], "an OFF face line")
    return vertices, _faces(raw, widths)


def _all_whole(raw: np.ndarray) -> bool:
    return bool(np.isfinite(raw).all() and (raw == np.round(raw)).all())


def _faces(raw: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Face lines `k i1 .. ik [colour]` -> (t, 3) fanned triangles."""
    starts = np.cumsum(widths) - widths
    if widths.size and widths.min() < 1:
        raise InvalidMeshError("an OFF face line is empty")
    k = raw[starts]
    if k.size and (not _all_whole(k) or k.min() < 3):
        raise InvalidMeshError("an OFF face line must start with its number of corners (3 or more)")
    k = k.astype(np.int64)
    if (widths < k + 1).any():
        raise InvalidMeshError("an OFF face line lists fewer corners than its count says")
    corners = np.repeat(starts + 1, k) + np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
    # colour columns after the corners may be fractional; the indices may not
    return fan_triangulate(whole_numbers(raw[corners], "an OFF face index"), k)
