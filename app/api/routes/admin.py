"""/admin: vocabulary and index maintenance (X-Admin-Token required)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, status

from app.api.deps import AdminDep, CtxDep, RuntimeDep
from app.api.schemas import ErrorResponse, JobAccepted, VocabularyPublic, VocabularyRebuild
from app.api.space import RoomDep
from app.core.descriptor import RUNS
from app.services import maintenance, refit
from app.services.errors import InvalidInputError

router = APIRouter(prefix="/admin", tags=["admin"], responses={401: {"model": ErrorResponse}})


def _enqueue(ctx, kind: str, payload: dict) -> JobAccepted:
    job_id, state = maintenance.enqueue_once(ctx, kind, payload)  # a pending one answers instead
    return JobAccepted(job_id=job_id, status=state, state=state)


# the data directory at its floor or quota (app/api/space.py)
FULL: dict[int | str, dict[str, Any]] = {507: {"model": ErrorResponse}}


@router.post(
    "/vocabulary/rebuild", status_code=status.HTTP_202_ACCEPTED, response_model=JobAccepted, responses=FULL
)
def rebuild_vocabulary(
    _: AdminDep, __: RoomDep, ctx: CtxDep, body: Annotated[VocabularyRebuild | None, Body()] = None
) -> JobAccepted:
    """Fit a new vocabulary on the stored descriptions, re-encode, re-index, swap (a job)."""
    body = body or VocabularyRebuild(size=ctx.settings.vocabulary_size, run=ctx.settings.vocabulary_run)
    if body.run not in RUNS:
        raise InvalidInputError(f"run must be one of {', '.join(RUNS)}")
    return _enqueue(ctx, "rebuild_vocabulary", body.model_dump())


@router.post(
    "/index/rebuild", status_code=status.HTTP_202_ACCEPTED, response_model=JobAccepted, responses=FULL
)
def rebuild_index(_: AdminDep, __: RoomDep, ctx: CtxDep) -> JobAccepted:
    """Re-encode every model with the active vocabulary from its cached description (a job)."""
    return _enqueue(ctx, "rebuild_index", {})


@router.get("/vocabulary", response_model=VocabularyPublic)
def get_vocabulary(_: AdminDep, runtime: RuntimeDep) -> VocabularyPublic:
    active, versions = maintenance.vocabulary_versions(runtime.ctx)
    live = runtime.live.status()
    next_refit_at = refit.refit_status(runtime.ctx)[1]
    if active is None:
        return VocabularyPublic(versions=versions, next_refit_at=next_refit_at)
    return VocabularyPublic(
        id=active.id,
        words=active.size,
        run=active.run,
        trained_on_descriptors=active.trained_on,
        created_at=active.created_at,
        indexed_models=live["indexed"] if live["vocabulary_id"] == active.id else 0,
        versions=versions,
        metadata=active.metadata,
        next_refit_at=next_refit_at,
    )
