"""What a stored model needs to be viewed, computed once and kept: its explain geometry (at ingest, else
on first use) and its thumbnails (on first use), under the data directory (BlobStore.view_path,
thumbnail_path).

A failure is kept too (`<what>.failed`, holding the reason): the next view answers at once, a thumbnail
with a placeholder image, an explanation with a 422 naming the reason, instead of decoding and failing
again on every view (a needle's thumbnail used to fail, or run into the time limit, on each request).
Only refusals that say nothing about the model (a busy pool, a client over its share, a deleted model)
are not kept. Concurrent first views of the same thing share one computation (QueryDescriber.shared).
"""

from __future__ import annotations

import asyncio
import io
import logging
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from app.core.mesh import Mesh
from app.services import rendering
from app.services.clients import ClientOverBudget
from app.services.context import ServiceContext
from app.services.errors import InvalidInputError, NotFoundError, PoolBusyError
from app.services.explain import Geometry, from_canonical, stored_geometry
from app.services.query_pool import QueryDescriber
from app.storage import models as models_repo
from app.storage.blobs import atomic_write
from app.storage.models import ModelRecord

log = logging.getLogger(__name__)

GEOMETRY = "geometry.npz"
NOT_KEPT = (PoolBusyError, ClientOverBudget, NotFoundError)  # about the moment, not the model
PLACEHOLDER_HEADER = "X-Shapebag-Placeholder"  # set on a placeholder thumbnail: why there is no picture


# ---- explain geometry -----------------------------------------------------------------------------------


def save_geometry(ctx: ServiceContext, model_id: int, fine: Mesh) -> None:
    """At ingest: the canonical-resolution mesh the description was made on, in the view frame.
    Any failure is kept as the geometry's failure (the model itself is still ingested)."""
    try:
        geometry = from_canonical(fine)
        _write_geometry(ctx.blobs.view_path(model_id, GEOMETRY), geometry)
    except Exception as exc:  # a view's failure must never fail the ingest
        log.warning("model %d: explain geometry not kept: %s", model_id, exc)
        _keep_failure(ctx, model_id, "geometry", f"its geometry could not be prepared: {exc}")


def save_thumbnail(
    ctx: ServiceContext, model_id: int, mesh: Mesh, size: int = rendering.PREVIEW_SIZE
) -> None:
    """At ingest: the thumbnail a results page shows, so a first Browse loads pictures, not renders
    (ten at once from one page would wait on the render budget). A failure is kept as on a view."""
    what = f"thumbnail-{size}"
    try:
        png = rendering.render_mesh(mesh, size)
    except Exception as exc:  # a view's failure must never fail the ingest
        _keep_failure(ctx, model_id, what, _reason(exc))
        return
    atomic_write(ctx.blobs.thumbnail_path(model_id, size), png)


def _write_geometry(path: Path, g: Geometry) -> None:
    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, vertices=g.vertices.astype(np.float32), faces=g.faces.astype(np.int32))

    atomic_write(path, write)


def _read_geometry(path: Path) -> Geometry:
    with np.load(path, allow_pickle=False) as z:
        return Geometry(z["vertices"], z["faces"])


async def explain_geometry(ctx: ServiceContext, pool: QueryDescriber, model: ModelRecord) -> Geometry:
    """The kept geometry; computed in the explain budget the first time (models ingested before it was
    kept at ingest); a kept failure is InvalidInputError (422) at once."""
    path = ctx.blobs.view_path(model.id, GEOMETRY)
    if await asyncio.to_thread(path.is_file):
        return await asyncio.to_thread(_read_geometry, path)
    reason = await asyncio.to_thread(_failure, ctx, model.id, "geometry")
    if reason is not None:
        raise InvalidInputError(f"model {model.id} cannot be explained: {reason}")

    async def compute() -> Geometry:
        mesh = str(ctx.blobs.mesh_path(model.sha256, model.file_type))
        args = (mesh, model.file_type, ctx.settings.describe.params(), ctx.settings.max_vertices)
        try:
            geometry = await pool.run(stored_geometry, args, "reading the model's mesh", kind="explain")
        except NOT_KEPT:
            raise
        except Exception as exc:
            reason = _reason(exc)
            await asyncio.to_thread(_keep_failure, ctx, model.id, "geometry", reason)
            raise InvalidInputError(f"model {model.id} cannot be explained: {reason}") from exc
        await asyncio.to_thread(_write_geometry, path, geometry)
        await _gone_unless_exists(ctx, model.id, path)
        return geometry

    return await pool.shared(("geometry", ctx.data_dir, model.id), compute)


# ---- thumbnails -----------------------------------------------------------------------------------------


async def thumbnail(
    ctx: ServiceContext, pool: QueryDescriber, model: ModelRecord, size: int
) -> tuple[bytes, str | None]:
    """(PNG bytes, None), or (a placeholder PNG, the reason) when rendering failed, now or before."""
    path = ctx.blobs.thumbnail_path(model.id, rendering.check_size(size))
    what = f"thumbnail-{size}"
    if await asyncio.to_thread(path.is_file):
        return await asyncio.to_thread(path.read_bytes), None
    reason = await asyncio.to_thread(_failure, ctx, model.id, what)
    if reason is not None:
        return placeholder(size), reason

    async def render() -> tuple[bytes, str | None]:
        mesh = str(ctx.blobs.mesh_path(model.sha256, model.file_type))
        args = (mesh, model.file_type, ctx.settings.max_vertices, size, model.id)
        try:
            png = await pool.run(rendering.render_stored, args, "rendering the thumbnail", kind="render")
        except NOT_KEPT:
            raise
        except Exception as exc:
            reason = _reason(exc)
            await asyncio.to_thread(_keep_failure, ctx, model.id, what, reason)
            return placeholder(size), reason
        await asyncio.to_thread(atomic_write, path, png)
        await _gone_unless_exists(ctx, model.id, path)
        return png, None

    return await pool.shared((what, ctx.data_dir, model.id), render)


def placeholder(size: int) -> bytes:
    """A light grey frame with a diagonal cross: 'no picture', the same for every failure."""
    img = Image.new("RGBA", (size, size), (0, 0, 0, 0))
    draw = ImageDraw.Draw(img)
    m, w = size // 8, max(1, size // 64)
    grey = (176, 182, 190, 255)
    draw.rectangle((m, m, size - m, size - m), outline=grey, width=w)
    draw.line((m, m, size - m, size - m), fill=grey, width=w)
    draw.line((m, size - m, size - m, m), fill=grey, width=w)
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


# ---- kept failures --------------------------------------------------------------------------------------


def _reason(exc: BaseException) -> str:
    text = getattr(exc, "message", None) or str(exc) or type(exc).__name__
    return " ".join(text.split())[:500]


def _keep_failure(ctx: ServiceContext, model_id: int, what: str, reason: str) -> None:
    path = ctx.blobs.view_path(model_id, f"{what}.failed")
    atomic_write(path, reason.encode("utf-8"))
    if not _exists(ctx, model_id):
        path.unlink(missing_ok=True)


def _failure(ctx: ServiceContext, model_id: int, what: str) -> str | None:
    try:
        return ctx.blobs.view_path(model_id, f"{what}.failed").read_text("utf-8", errors="replace")
    except FileNotFoundError:
        return None


async def _gone_unless_exists(ctx: ServiceContext, model_id: int, path: Path) -> None:
    """Checked after a view file is written: a delete removes view files after its commit, so either
    it sees this file or this check sees the model gone (no orphan file)."""
    if not await asyncio.to_thread(_exists, ctx, model_id):
        path.unlink(missing_ok=True)
        raise NotFoundError(f"no model with id {model_id}")


def _exists(ctx: ServiceContext, model_id: int) -> bool:
    with ctx.db.read() as conn:
        return models_repo.get(conn, model_id) is not None
