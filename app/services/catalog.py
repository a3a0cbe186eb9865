"""The collection: list, read, delete models and jobs (delete = gone from index, database and blobs)."""

from __future__ import annotations

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
    if live is not None:
        live.remove([model_id])
    ctx.blobs.delete_model_files(model_id, model.sha256, model.file_type)
