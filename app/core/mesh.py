"""Triangle meshes in: load, validate, clean.

Everything a user can upload passes through :func:`load_mesh`, which raises :class:`InvalidMeshError`
(or its :class:`UnsupportedFormatError`) with a sentence a user understands. The numerical core
downstream may then assume a finite, indexed, non-degenerate triangle mesh with positive area.

The pieces live in small modules and are re-exported here: the readers in app/core/formats, the mesh
value and errors in app/core/meshdata.py, validation and cleaning in app/core/cleaning.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.core.cleaning import (
    clean,
    drop_unreferenced,
    face_components,
    merge_vertices,
    unique_face_index,
    validate,
    vertex_components,
)
from app.core.formats import SUPPORTED_FORMATS, detect_format, parse
from app.core.meshdata import MIN_FACES, MIN_VERTICES, Budget, InvalidMeshError, Mesh, UnsupportedFormatError

__all__ = [
    "MIN_FACES",
    "MIN_VERTICES",
    "SUPPORTED_FORMATS",
    "InvalidMeshError",
    "Mesh",
    "UnsupportedFormatError",
    "clean",
    "detect_format",
    "drop_unreferenced",
    "face_components",
    "load_mesh",
    "merge_vertices",
    "unique_face_index",
    "validate",
    "vertex_components",
]


def load_mesh(
    source: bytes | str | Path, file_type: str | None = None, max_vertices: int | None = None
) -> Mesh:
    """Read a mesh from bytes (file_type required: a name or an extension) or a path; validate and clean.

    max_vertices bounds the work a single upload can cause. It applies to the cleaned mesh (after
    welding: a binary STL stores 3 vertices per triangle), and the counts a file declares are checked
    against it before its arrays are allocated (meshdata.Budget), so a huge file is refused cheaply.
    """
    if isinstance(source, (str, Path)):
        path = Path(source)
        file_type = detect_format(file_type or path.name)
        data = path.read_bytes()
    else:
        if file_type is None:
            raise InvalidMeshError("the mesh format is unknown: give a file name with an extension")
        file_type = detect_format(file_type)
        data = source
    if len(data) == 0:
        raise InvalidMeshError("the file is empty")
    vertices, faces = _parse(data, file_type, max_vertices)
    mesh = clean(validate(vertices, faces))
    if max_vertices is not None and mesh.n_vertices > max_vertices:
        raise InvalidMeshError(
            f"the mesh has {mesh.n_vertices} vertices once duplicates are welded, more than the limit"
            f" of {max_vertices}"
        )
    return mesh


def _parse(data: bytes, file_type: str, max_vertices: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Raw (vertices (n, 3) float64, faces (f, 3) int64) as the file holds them (benchmarks use this)."""
    return parse(data, file_type, Budget(max_vertices))
