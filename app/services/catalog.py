"""The collection: list, read, delete models and jobs (delete = gone from index, database and blobs)."""

from __future__ import annotations

import os
from pathlib import Path

from app.services.context import ServiceContext
from app.services.errors import InvalidInputError, NotFoundError
from app.services.live_index import LiveIndex
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage.jobs import JobRecord
from app.storage.models import ModelRecord

STATUSES = ("queued", "ready", "failed")


def list_models(
    ctx: ServiceContext, label: str | None, status: str | None, limit: int, offset: int
) -> tuple[list[ModelRecord], int]:
    if status is not None and status not in STATUSES:
        raise InvalidInputError(f"status must be one of {', '.join(STATUSES)}")
    with ctx.db.read() as conn:
        return models_repo.page(conn, label=label, status=status, limit=limit, offset=offset)


def labels(ctx: ServiceContext) -> list[tuple[str, int]]:
    """Every label in use and how many models carry it, by name."""
    with ctx.db.read() as conn:
        return models_repo.label_counts(conn)


def get_model(ctx: ServiceContext, model_id: int) -> ModelRecord:
    with ctx.db.read() as conn:
        model = models_repo.get(conn, model_id)
    if model is None:
        raise NotFoundError(f"no model with id {model_id}")
    return model


def get_job(ctx: ServiceContext, job_id: int) -> JobRecord:
    with ctx.db.read() as conn:
        job = jobs_repo.get(conn, job_id)
    if job is None:
        raise NotFoundError(f"no job with id {job_id}")
    return job


def delete_model(ctx: ServiceContext, live: LiveIndex | None, model_id: int) -> None:
    """Linearisable with an upload of the same bytes: the mesh file leaves under the write lock, in
    the same transaction as the row, and ingestion.submit re-writes a missing file under that lock
    before it inserts. So a new model never points at a file a delete is about to remove."""
    hidden: Path | None = None
    home: Path | None = None
    try:
        with ctx.db.write() as conn:
            model = models_repo.get(conn, model_id)
            if model is None:
                raise NotFoundError(f"no model with id {model_id}")
            models_repo.delete(conn, model_id)  # cascades to its BoF vectors
            conn.execute(
                "UPDATE jobs SET state = 'failed', error = 'model deleted', lease_until = NULL"
                " WHERE model_id = ? AND state = 'queued'",
                (model_id,),
            )
            if models_repo.get_by_sha256(conn, model.sha256) is None:  # no other model holds the content
                home = ctx.blobs.mesh_path(model.sha256, model.file_type)
                hidden = ctx.blobs.hide_mesh(model.sha256, model.file_type, conn)
    except BaseException:
        if hidden is not None and home is not None:  # rolled back: the row is there, so is its file
            os.replace(hidden, home)
        raise
    if hidden is not None:
        hidden.unlink(missing_ok=True)
    if live is not None:
        live.remove([model_id])
    ctx.blobs.delete_model_files(model_id)  # description and thumbnails: named by id, never shared
