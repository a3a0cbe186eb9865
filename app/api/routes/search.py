"""POST /search: describe the query mesh in the process pool, encode, rank by L1 distance."""

from __future__ import annotations

import time
from dataclasses import replace

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool

from app.api import limits
from app.api.deps import RuntimeDep
from app.api.routes.models import ERRORS, to_response
from app.api.schemas import PARTIAL, SearchResponse
from app.api.uploads import multipart_body, read_form
from app.services import search, variant_query
from app.services.errors import InvalidInputError

router = APIRouter(tags=["search"])

SEARCH_BODY = multipart_body(
    "the query mesh",
    k={"type": "integer", "default": 10, "minimum": 1, "maximum": search.MAX_K},
    label={"type": "string", "description": "only return models with this label"},
    partial={"type": "string", "enum": ["auto", "true", "false"], "default": "auto",
             "description": "re-rank the nearest models by partial matching: auto does it for a query with "
                            "a free boundary (a piece, a one-sided scan); true / false force it"},
)


@router.post(
    "/search",
    response_model=SearchResponse,
    responses={**ERRORS, 415: ERRORS[422], 504: ERRORS[422]},
    openapi_extra=SEARCH_BODY,
)
async def search_mesh(request: Request, runtime: RuntimeDep) -> SearchResponse:
    t = time.perf_counter()
    form = await read_form(request, runtime.ctx.settings.max_upload_bytes)
    filename, data = form.file("file")
    limits.check_form(form)
    try:
        k = search.check_k(int(form.fields.get("k") or 10))
    except ValueError as exc:
        raise InvalidInputError(f"k must be an integer between 1 and {search.MAX_K}") from exc
    choice = (form.fields.get("partial") or "auto").lower()
    if choice not in PARTIAL:
        raise InvalidInputError(f"partial must be auto, true or false, not {choice[:20]!r}")
    runtime.live.require()  # fail fast, before the expensive part, when nothing can answer
    seconds = {"upload": time.perf_counter() - t}
    t = time.perf_counter()
    deadline = time.monotonic() + runtime.describer.timeout_s  # the query pool's, for the variant step
    description, stages = await runtime.describer.describe(data, limits.upload_format(filename))
    describe_wall = time.perf_counter() - t
    runtime.metrics.describe_seconds.labels("query").observe(describe_wall)
    seconds.update({f"describe.{name}": v for name, v in stages.items()})
    seconds["describe"] = describe_wall
    label = form.fields.get("label") or None
    result = await run_in_threadpool(
        search.search_description, runtime.ctx, runtime.live, description, k, label, PARTIAL[choice],
        runtime.pieces,
    )
    seconds.update(result.seconds)
    t = time.perf_counter()
    hit_ids = [h.model.id for h in result.hits]
    found = await variant_query.relations(
        runtime.ctx, runtime.describer, data, limits.upload_format(filename), hit_ids, deadline
    )
    seconds["variants"] = time.perf_counter() - t
    seconds["total"] = sum(v for name, v in seconds.items() if "." not in name)
    relations = {i: e["relation"] for i, e in found.items()}
    return to_response(replace(result, seconds=seconds), relations, found)
