"""What the service accepts from users, on top of core validation: `load_upload` = load_mesh + surface checks.

Used wherever a mesh comes from outside (API uploads and queries, `shapebag search FILE`), so that every
door refuses the same inputs with the same words. Runs in a pool process (see QueryDescriber.check).
"""

from __future__ import annotations

from pathlib import Path

from app.core.cleaning import nonmanifold_faces
from app.core.mesh import InvalidMeshError, Mesh, load_mesh

# a few non-manifold edges are common in real scans and harmless; a surface made mostly of them
# (fans of triangles hinged on one edge) has no meaningful Laplace-Beltrami spectrum
MAX_NONMANIFOLD_FACE_FRACTION = 0.1


def check_surface(mesh: Mesh) -> Mesh:
    """Raise InvalidMeshError when the mesh is mostly non-manifold; else return it."""
    bad = int(nonmanifold_faces(mesh.faces).sum())
    if bad > MAX_NONMANIFOLD_FACE_FRACTION * mesh.n_faces:
        raise InvalidMeshError(
            f"the mesh is not a surface: {bad} of its {mesh.n_faces} faces meet at edges shared by"
            " more than two faces (non-manifold)"
        )
    return mesh


def load_upload(source: bytes | str | Path, file_type: str | None, max_vertices: int | None) -> Mesh:
    """load_mesh (parse, validate, clean, vertex limit) + check_surface."""
    return check_surface(load_mesh(source, file_type, max_vertices=max_vertices))


def check_bytes(data: bytes, file_type: str, max_vertices: int | None) -> int:
    """Pool-process entry: validate an upload; returns its vertex count (after cleaning)."""
    return load_upload(data, file_type, max_vertices).n_vertices
