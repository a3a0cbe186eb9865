"""/jobs/{id}: queued / running / done / failed with the reason, and timings."""

from __future__ import annotations

from fastapi import APIRouter

from app.api.deps import CtxDep
from app.api.limits import IdPath
from app.api.schemas import ErrorResponse, JobPublic
from app.services import catalog

router = APIRouter(prefix="/jobs", tags=["jobs"])


@router.get("/{job_id}", response_model=JobPublic, responses={404: {"model": ErrorResponse}})
def get_job(job_id: IdPath, ctx: CtxDep) -> JobPublic:
    return JobPublic.of(catalog.get_job(ctx, job_id))
