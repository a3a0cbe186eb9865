"""Why it matched: GET /models/{id}/explain?against={other} and POST /explain (an uploaded query).

Each shape comes back at the canonical resolution (the vertices the words live on) with its word per
vertex, keypoints and BoF histogram; with `against`, the words that contribute most to the L1 distance.
The web page's 3D viewer draws these (app/api/static/viewer.js); API users get the same numbers.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from fastapi import APIRouter, Query, Request
from fastapi.concurrency import run_in_threadpool

from app.api import limits
from app.api.deps import Runtime, RuntimeDep
from app.api.limits import IdPath
from app.api.routes.models import ERRORS
from app.api.schemas import Explanation, ShapeExplained, WordContribution
from app.api.uploads import multipart_body, read_form
from app.services import catalog, explain, views
from app.services.errors import InvalidInputError
from app.services.live_index import ActivePair

router = APIRouter(tags=["explain"])
AgainstQuery = Annotated[
    int | None, Query(ge=1, le=2**63 - 1, description="another model: both coloured, words ranked")
]
EXPLAIN_BODY = multipart_body(
    "the query mesh",
    against={
        "type": "integer",
        "minimum": 1,
        "maximum": 2**63 - 1,
        "description": "the model to compare it with",
    },
)


async def _stored(runtime: Runtime, pair: ActivePair, model_id: int) -> explain.Side:
    ctx = runtime.ctx
    model = await run_in_threadpool(catalog.get_model, ctx, model_id)
    description = await run_in_threadpool(explain.stored_description, ctx, model)
    geometry = await views.explain_geometry(ctx, runtime.describer, model)  # kept; computed once
    return explain.side(model, model.name, description, geometry, pair.vocabulary, pair.params)


@router.get("/models/{model_id}/explain", response_model=Explanation, responses={**ERRORS, 409: ERRORS[404]})
async def explain_model(model_id: IdPath, runtime: RuntimeDep, against: AgainstQuery = None) -> Explanation:
    """The model's words per vertex, keypoints and BoF; with `against`, the same for that model and the
    words that separate the two."""
    pair = runtime.live.require()
    shape = await _stored(runtime, pair, model_id)
    other = await _stored(runtime, pair, against) if against is not None else None
    return to_response(explain.explain(pair.record.id, pair.vocabulary, shape, other))


@router.post(
    "/explain",
    response_model=Explanation,
    responses={**ERRORS, 409: ERRORS[404], 415: ERRORS[422], 504: ERRORS[422]},
    openapi_extra=EXPLAIN_BODY,
)
async def explain_upload(request: Request, runtime: RuntimeDep) -> Explanation:
    """An uploaded query (described again, as /search does) against a stored model."""
    settings = runtime.ctx.settings
    form = await read_form(request, settings.max_upload_bytes)
    filename, data = form.file("file")
    limits.check_form(form)
    try:
        against = int(form.fields.get("against") or "")
    except ValueError as exc:
        raise InvalidInputError("against: the id of a stored model is required") from exc
    if not 1 <= against < 2**63:
        raise InvalidInputError("against: the id of a stored model is required")
    pair = runtime.live.require()
    other = await _stored(runtime, pair, against)  # first: a wrong id fails before the costly part
    args = (data, limits.upload_format(filename), settings.describe.params(), settings.max_vertices)
    description, geometry = await runtime.describer.run(
        explain.query_geometry, args, "explaining the query", kind="explain"
    )
    shape = explain.side(None, filename, description, geometry, pair.vocabulary, pair.params)
    return to_response(explain.explain(pair.record.id, pair.vocabulary, shape, other))


def _shape(s: explain.Side) -> ShapeExplained:
    return ShapeExplained(
        model_id=s.model_id,
        name=s.name,
        label=s.label,
        vertices=np.round(s.geometry.vertices.astype(np.float64), 5).ravel().tolist(),  # compact JSON
        faces=s.geometry.faces.ravel().tolist(),
        words=s.seen.words.tolist(),
        keypoints=s.seen.keypoints.tolist(),
        bof=s.seen.bof.astype(np.float64).tolist(),
    )


def to_response(e: explain.Explanation) -> Explanation:
    top: list[WordContribution] = []
    if e.against is not None and e.terms is not None and e.top is not None:
        a, b, t = e.shape.seen.bof, e.against.seen.bof, e.terms
        top = [
            WordContribution(word=int(w), shape=float(a[w]), against=float(b[w]), contribution=float(t[w]))
            for w in e.top
        ]
    return Explanation(
        vocabulary_id=e.vocabulary_id,
        words=e.size,
        shape=_shape(e.shape),
        against=_shape(e.against) if e.against is not None else None,
        bof_l1=float(e.terms.sum()) if e.terms is not None else None,
        distance=e.distance,
        top_words=top,
    )
