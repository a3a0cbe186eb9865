"""Admin-side questions and requests: maintenance jobs, the active vocabulary, live workers, thumbnails."""

from __future__ import annotations

import asyncio
from pathlib import Path

from app.services import rendering
from app.services.context import ServiceContext
from app.services.errors import NotFoundError
from app.services.query_pool import QueryDescriber
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.storage.blobs import atomic_write
from app.storage.models import ModelRecord
from app.storage.vocabularies import VocabularyRecord


def enqueue_once(ctx: ServiceContext, kind: str, payload: dict) -> tuple[int, str]:
    """(job id, state) of a maintenance job; one at a time: a pending one of that kind is returned."""
    with ctx.db.write() as conn:
        running = jobs_repo.pending(conn, kind)
        if running is not None:
            return running.id, running.state
        return jobs_repo.enqueue(conn, kind, payload=payload), "queued"


def vocabulary_versions(ctx: ServiceContext) -> tuple[VocabularyRecord | None, int]:
    """The active vocabulary version (None before the first) and how many versions exist."""
    with ctx.db.read() as conn:
        return vocab_repo.active(conn), len(vocab_repo.all_versions(conn))


def live_workers(ctx: ServiceContext) -> int:
    """Workers (embedded or `shapebag worker`) whose heartbeat is recent."""
    with ctx.db.read() as conn:
        return jobs_repo.live_workers(conn, within_s=max(10.0, ctx.settings.lease_seconds))


async def thumbnail_file(ctx: ServiceContext, pool: QueryDescriber, model: ModelRecord, size: int) -> Path:
    """The cached PNG rendering of a stored mesh, rendered on first request in a pool process (under
    its memory cap and time limit) at one of rendering.THUMBNAIL_SIZES."""
    path = ctx.blobs.thumbnail_path(model.id, rendering.check_size(size))
    if not path.is_file():
        mesh_path = str(ctx.blobs.mesh_path(model.sha256, model.file_type))
        args = (mesh_path, model.file_type, ctx.settings.max_vertices, size, model.id)
        png = await pool.run(rendering.render_stored, args, "rendering the thumbnail", kind="render")
        await asyncio.to_thread(atomic_write, path, png)
        if not await asyncio.to_thread(_exists, ctx, model.id):  # deleted while rendering: no orphan file
            path.unlink(missing_ok=True)
            raise NotFoundError(f"no model with id {model.id}")
    return path


def _exists(ctx: ServiceContext, model_id: int) -> bool:
    """Checked after the thumbnail is written: a delete removes thumbnails after its commit, so either
    it sees this file or this check sees the model gone."""
    with ctx.db.read() as conn:
        return models_repo.get(conn, model_id) is not None
