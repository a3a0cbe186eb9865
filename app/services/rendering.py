"""Mesh -> PNG, run in a query-pool process (never the API process): decode and rasterise cost memory
in proportion to the mesh, so they run under the pool's memory cap and time limit (QueryDescriber.run).

Thumbnails come in a few fixed sizes only, so the cache holds at most len(THUMBNAIL_SIZES) files per
model (before, any size from 32 to 1024 was rendered and cached: 45 sizes of one model took 14 GB).
"""

from __future__ import annotations

from pathlib import Path

from app.core.mesh import InvalidMeshError, Mesh, load_mesh
from app.core.resolution import simplify
from app.services.errors import InvalidInputError, NotFoundError
from app.services.mesh_policy import load_upload
from app.services.thumbnails import RenderTooCostlyError, render_png

PREVIEW_SIZE = 256
THUMBNAIL_SIZES = (128, 256, 512)
RENDER_MAX_VERTICES = 100_000  # bigger meshes are rendered from a decimated copy


def check_size(size: int) -> int:
    if size not in THUMBNAIL_SIZES:
        raise InvalidInputError(
            f"size must be one of {', '.join(map(str, THUMBNAIL_SIZES))} pixels, got {size}"
        )
    return size


def _png(mesh: Mesh, size: int) -> bytes:
    if mesh.n_vertices > RENDER_MAX_VERTICES:
        mesh = simplify(mesh, RENDER_MAX_VERTICES)
    try:
        return render_png(mesh.vertices, mesh.faces, size)
    except RenderTooCostlyError as exc:  # the mesh's, not the server's: 422 (a kept placeholder for a model)
        raise InvalidInputError(f"the mesh cannot be rendered: {exc}") from exc


def render_mesh(mesh: Mesh, size: int = PREVIEW_SIZE) -> bytes:
    """A loaded mesh's thumbnail (at ingest, in a worker process)."""
    return _png(mesh, check_size(size))


def render_upload(data: bytes, file_type: str, max_vertices: int, size: int = PREVIEW_SIZE) -> bytes:
    """An uploaded mesh (the web page's query preview): refused as an upload would be (InvalidMeshError)."""
    return _png(load_upload(data, file_type, max_vertices), size)


def render_stored(path: str, file_type: str, max_vertices: int, size: int, model_id: int) -> bytes:
    """A stored model's thumbnail."""
    try:
        mesh = load_mesh(Path(path), file_type, max_vertices=max_vertices)
    except FileNotFoundError:  # deleted while we were asked
        raise NotFoundError(f"no model with id {model_id}") from None
    except (InvalidMeshError, ValueError) as exc:
        raise InvalidInputError(f"model {model_id} has no renderable mesh: {exc}") from exc
    return _png(mesh, check_size(size))
