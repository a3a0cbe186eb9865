"""/models/{id}/variants: the stored models related to this one, with the evidence, and reviewers'
decisions about a pair (recorded, never acted on: shapebag deletes and merges nothing)."""

from __future__ import annotations

from fastapi import APIRouter, status
from fastapi.concurrency import run_in_threadpool

from app.api.deps import CtxDep, UploadDep
from app.api.limits import IdPath, check_text
from app.api.schemas import (
    ErrorResponse,
    VariantDecision,
    VariantDecisionPublic,
    VariantPublic,
    VariantsPublic,
)
from app.api.space import RoomDep
from app.services import variants

router = APIRouter(prefix="/models", tags=["variants"])
ERRORS: dict[int | str, dict] = {c: {"model": ErrorResponse} for c in (404, 422)}


@router.get("/{model_id}/variants", response_model=VariantsPublic, responses=ERRORS)
def list_variants(model_id: IdPath, ctx: CtxDep) -> VariantsPublic:
    """Models found to be this one identical, moved, rescaled, mirrored, re-triangulated, part of it or
    holding it, best first, each with distances, scale, transform and the latest reviewer decision."""
    rows = variants.variants_of(ctx, model_id)
    return VariantsPublic(data=[VariantPublic.model_validate(r) for r in rows], count=len(rows))


@router.post(
    "/{model_id}/variants/{other_id}/decision",
    status_code=status.HTTP_201_CREATED,
    response_model=VariantDecisionPublic,
    responses={**ERRORS, 401: ERRORS[404]},
)
async def decide(
    model_id: IdPath, other_id: IdPath, body: VariantDecision, ctx: CtxDep, _: UploadDep, __: RoomDep
) -> VariantDecisionPublic:
    """Record a reviewer's decision about the pair: `keep_both` or `not_variant`. It is kept (the latest
    one shows on GET .../variants, the pair's last ten are stored); the models themselves are never
    changed. A write like an upload: the API token when one is set, and refused (507) when the data
    directory is at its floor or quota."""
    check_text("note", body.note)
    row = await run_in_threadpool(variants.decide, ctx, model_id, other_id, body.decision, body.note)
    return VariantDecisionPublic.model_validate(row)
