"""/models: upload, browse, fetch, delete, similar, thumbnail."""

from __future__ import annotations

import mimetypes
from typing import Annotated, Literal

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, JSONResponse
from pydantic import ValidationError

from app.api import limits
from app.api.deps import CtxDep, DeleteDep, RuntimeDep, UploadDep
from app.api.limits import IdPath
from app.api.schemas import (
    PARTIAL,
    ErrorResponse,
    MatchedRegion,
    ModelAccepted,
    ModelCreate,
    ModelPublic,
    ModelsPublic,
    PartialWork,
    PieceFitPublic,
    SearchHit,
    SearchResponse,
)
from app.api.space import RoomDep
from app.api.uploads import multipart_body, read_form
from app.core.partial_match import Region
from app.core.piece_fit import PieceFit
from app.services import catalog, ingestion, metadata, rendering, search, variants, views
from app.services.errors import InvalidInputError, NotFoundError

router = APIRouter(prefix="/models", tags=["models"])
ERRORS: dict[int | str, dict] = {c: {"model": ErrorResponse} for c in (404, 413, 422, 503)}
WRITE_ERRORS = {**ERRORS, 401: ERRORS[404]}

UPLOAD_BODY = multipart_body(
    "the mesh file",
    name={"type": "string", "minLength": 1, "maxLength": limits.MAX_TEXT_CHARS},
    label={"type": "string", "minLength": 1, "maxLength": 100},
    metadata={
        "type": "string",
        "description": "a JSON object",
        "maxLength": metadata.MAX_METADATA_BYTES,
    },
)


@router.post(
    "",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=ModelAccepted,
    responses={
        **WRITE_ERRORS,
        **{c: ERRORS[422] for c in (415, 504, 507)},
    },  # compressed body, time limit, disk
    openapi_extra=UPLOAD_BODY,
)
async def upload_model(request: Request, runtime: RuntimeDep, _: UploadDep, __: RoomDep) -> JSONResponse:
    """Store a mesh and queue its ingestion (202); identical content answers 200 with the existing model."""
    ctx = runtime.ctx
    form = await read_form(request, ctx.settings.max_upload_bytes)
    filename, data = form.file("file")
    limits.check_form(form)
    try:
        fields = ModelCreate(
            name=form.fields.get("name") or None,
            label=form.fields.get("label") or None,
            metadata=metadata.parse_metadata(form.fields.get("metadata")),
        )
    except ValidationError as exc:
        first = exc.errors()[0]
        raise InvalidInputError(f"{'.'.join(map(str, first['loc']))}: {first['msg']}") from exc
    await runtime.describer.check(data, limits.upload_format(filename))  # a bad mesh: 422, nothing stored
    result = await run_in_threadpool(
        ingestion.submit, ctx, data, filename, fields.name, fields.label, fields.metadata
    )
    known = None if result.created else await run_in_threadpool(variants.brief, ctx, result.model.id)
    body = ModelAccepted(
        model_id=result.model.id,
        job_id=result.job_id,
        status=result.model.status,
        model=ModelPublic.of(result.model),
        variants=known,  # a new model's are found by its job (its result, then GET /models/{id})
        **_duplicate(result, fields.name, fields.label),
    )
    code = status.HTTP_202_ACCEPTED if result.job_id is not None else status.HTTP_200_OK  # new or retried
    return JSONResponse(body.model_dump(), status_code=code)


def _duplicate(result: ingestion.Submitted, name: str | None, label: str | None) -> dict:
    """duplicate_of + note when the bytes were already stored: say which model, and what was not applied."""
    if result.created:
        return {}
    m = result.model
    note = f"identical content is already stored as model {m.id} ({m.name!r})"
    sent = (("name", name, m.name), ("label", label, m.label))
    ignored = [field for field, given, kept in sent if given and given != kept]
    if ignored:
        verb = "were" if len(ignored) > 1 else "was"
        note += f"; its stored {' and '.join(ignored)} {verb} kept, not the one(s) sent"
    if result.job_id is not None:
        note += "; it had failed, so it is queued again"
    return {"duplicate_of": m.id, "note": note}


@router.get("", response_model=ModelsPublic)
def list_models(
    ctx: CtxDep,
    label: str | None = None,
    status: Literal["queued", "ready", "failed"] | None = None,  # catalog.STATUSES
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: limits.OffsetQuery = 0,
) -> ModelsPublic:
    rows, total = catalog.list_models(ctx, label, status, limit, offset)
    return ModelsPublic(data=[ModelPublic.of(m) for m in rows], count=total)


@router.get("/{model_id}", response_model=ModelPublic, responses=ERRORS)
def get_model(model_id: IdPath, ctx: CtxDep) -> ModelPublic:
    model = catalog.get_model(ctx, model_id)
    stored = ctx.blobs.model_bytes(model.id, model.sha256, model.file_type)
    return ModelPublic.of(model).model_copy(
        update={"stored_bytes": stored, "variants": variants.brief(ctx, model_id)}
    )


@router.get("/{model_id}/mesh", responses=ERRORS, response_class=FileResponse)
def get_mesh(model_id: IdPath, ctx: CtxDep) -> FileResponse:
    model = catalog.get_model(ctx, model_id)
    path = ctx.blobs.mesh_path(model.sha256, model.file_type)
    if not path.is_file():  # deleted a moment ago (the file leaves in the delete's transaction)
        raise NotFoundError(f"no model with id {model_id}")
    media = mimetypes.guess_type(f"x.{model.file_type}")[0] or "application/octet-stream"
    return FileResponse(path, media_type=media, filename=f"{model.name}.{model.file_type}")


@router.delete("/{model_id}", status_code=status.HTTP_204_NO_CONTENT, responses=WRITE_ERRORS)
def delete_model(model_id: IdPath, runtime: RuntimeDep, _: DeleteDep) -> Response:
    """Gone from the index, the database and the blob store."""
    catalog.delete_model(runtime.ctx, runtime.live, model_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get("/{model_id}/similar", response_model=SearchResponse, responses=ERRORS)
def similar(
    model_id: IdPath,
    runtime: RuntimeDep,
    k: Annotated[int, Query(ge=1, le=search.MAX_K)] = 10,
    label: str | None = None,
    partial: Annotated[
        Literal["auto", "true", "false"],
        Query(description="rank it as POST /search ranks a piece: auto does for a model with a free boundary "
                          "(an open scan, a piece); true / false force it"),
    ] = "auto",
) -> SearchResponse:
    """The models nearest to a stored one, ranked as POST /search would rank its mesh."""
    result = search.similar(runtime.ctx, runtime.live, model_id, k, label, PARTIAL[partial], runtime.pieces)
    return to_response(result, variants.relations_with(runtime.ctx, model_id))


@router.get("/{model_id}/thumbnail.png", responses=ERRORS, response_class=Response)
async def thumbnail(
    model_id: IdPath,
    runtime: RuntimeDep,
    size: Annotated[
        int, Query(description="pixels", json_schema_extra={"enum": list(rendering.THUMBNAIL_SIZES)})
    ] = rendering.PREVIEW_SIZE,
) -> Response:
    """A server-side rendering of the stored mesh (kept under the data directory; 128, 256 or 512).
    A mesh that cannot be rendered gets a placeholder image, with the reason in X-Shapebag-Placeholder."""
    rendering.check_size(size)
    model = await run_in_threadpool(catalog.get_model, runtime.ctx, model_id)
    png, failed = await views.thumbnail(runtime.ctx, runtime.describer, model, size)
    headers = {"Cache-Control": "public, max-age=86400, immutable"}
    if failed is not None:  # the reason in a header: ASCII only, one line
        headers = {"Cache-Control": "no-cache", views.PLACEHOLDER_HEADER: _header_text(failed)}
    return Response(png, media_type="image/png", headers=headers)


def _header_text(text: str) -> str:
    return "".join(c if 32 <= ord(c) < 127 else "?" for c in text)[:300]


def _region(region: Region | None) -> MatchedRegion | None:
    if region is None:
        return None
    weights = [round(float(w), 5) for w in region.weight]  # 5 digits: a page of 100 hits stays small
    return MatchedRegion(vertices=[int(v) for v in region.vertex], weights=weights)


def _fit(fit: PieceFit | None) -> PieceFitPublic | None:
    if fit is None:
        return None
    return PieceFitPublic(lies_on=fit.lies_on, covered=round(fit.covered, 4), share=round(fit.share, 4),
                          mirrored=fit.similarity.mirrored)


def to_response(
    result: search.SearchResult,
    relations: dict[int, str] | None = None,
    evidence: dict[int, dict] | None = None,
) -> SearchResponse:
    """relations: {model id: verified variant relation to the query model}, shown on the hits;
    evidence: {model id: the numbers behind it}, where the query was verified just now."""
    relations, evidence = relations or {}, evidence or {}
    hits = [
        SearchHit(
            model_id=h.model.id, name=h.model.name, label=h.model.label, distance=h.distance, rank=h.rank,
            rerank_distance=h.rerank, forward=h.forward, reverse=h.reverse, partial=h.partial,
            region=_region(h.region), relation=relations.get(h.model.id), evidence=evidence.get(h.model.id),
            matched_object=h.part or None, fit=_fit(h.fit),
        )
        for h in result.hits
    ]
    work = result.partial
    partial = None if work is None else PartialWork(
        coarse_read=work.coarse_read, coarse_of=work.coarse_of, coarse_cut=work.coarse_cut,
        scored=work.scored, scored_of=work.scored_of, score_cut=work.score_cut,
        fitted=work.fitted, fitted_of=work.fitted_of, fit_cut=work.fit_cut,
    )
    return SearchResponse(
        data=hits, count=len(hits), vocabulary_id=result.vocabulary_id, seconds=result.seconds,
        partial=partial,
    )
