"""The web page: GET / (search by upload, browse the collection) and its static assets.

Plain HTML + vanilla JS + CSS from app/api/static (no build step, no CDN). The page talks to the
public JSON API only, plus POST /web/preview.png, which renders an uploaded query mesh to a thumbnail
so the results read like the paper's Figure 1 (query on the left, ranked answers on the right).
"""

from __future__ import annotations

import functools
import mimetypes
from pathlib import Path

from fastapi import APIRouter, Request, Response
from fastapi.responses import FileResponse, HTMLResponse

from app.api.deps import RuntimeDep
from app.api.limits import upload_format
from app.api.schemas import ErrorResponse
from app.api.uploads import multipart_body, read_form
from app.core.mesh import SUPPORTED_FORMATS
from app.services.errors import NotFoundError
from app.services.rendering import render_upload

router = APIRouter(tags=["web"])
STATIC_DIR = Path(__file__).resolve().parent.parent / "static"


@router.get("/", include_in_schema=False)
def index() -> HTMLResponse:
    """The page, its file picker and its hint filled in from the readers' list (one list of formats)."""
    return HTMLResponse(page_html(), headers={"Cache-Control": "no-cache"})


def page_html() -> str:
    html = (STATIC_DIR / "index.html").read_text(encoding="utf-8")
    accept = ",".join(f".{ext}" for ext in SUPPORTED_FORMATS)
    shown = " · ".join(ext.upper() for ext in SUPPORTED_FORMATS)
    return html.replace("{{ accept }}", accept).replace("{{ formats }}", shown)


@functools.cache
def _static_names() -> frozenset[str]:
    return frozenset(p.name for p in STATIC_DIR.iterdir() if p.is_file())


@router.get("/static/{name}", include_in_schema=False)
def static(name: str) -> FileResponse:
    """One flat directory of assets; anything not in it (or any path trick) is a 404."""
    if name not in _static_names():  # only names listed from the directory: no NUL, no path tricks
        raise NotFoundError(f"no static file {name[:100]!r}")
    path = STATIC_DIR / name
    media = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
    return FileResponse(path, media_type=media, headers={"Cache-Control": "no-cache"})


PREVIEW_ERRORS = {c: {"model": ErrorResponse} for c in (403, 413, 415, 422, 503, 504)}
PREVIEW = {
    **multipart_body("the mesh to render"),
    "responses": {"200": {"description": "the rendered mesh", "content": {"image/png": {}}}},
}


@router.post(
    "/web/preview.png",
    response_class=Response,
    responses=PREVIEW_ERRORS,  # type: ignore[arg-type]
    openapi_extra=PREVIEW,
    summary="Render an uploaded mesh as a PNG (the web page's query thumbnail; nothing is stored)",
)
async def preview(request: Request, runtime: RuntimeDep) -> Response:
    """Render the uploaded mesh (multipart `file`) as the page's query thumbnail; nothing is stored.

    Decoding and rendering run in a query-pool process (memory cap, time limit), never in this one."""
    settings = runtime.ctx.settings
    form = await read_form(request, settings.max_upload_bytes)
    filename, data = form.file("file")
    args = (data, upload_format(filename), settings.max_vertices)
    png = await runtime.describer.run(render_upload, args, "rendering the preview", kind="render")
    return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})
