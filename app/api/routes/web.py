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
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse

from app.api.deps import SettingsDep
from app.api.uploads import read_form
from app.core.mesh import detect_format
from app.core.resolution import simplify
from app.services.errors import NotFoundError
from app.services.mesh_policy import load_upload
from app.services.thumbnails import render_png

router = APIRouter(tags=["web"])
STATIC_DIR = Path(__file__).resolve().parent.parent / "static"
PREVIEW_SIZE = 256
PREVIEW_MAX_VERTICES = 100_000  # previews of bigger meshes are rendered from a decimated copy


@router.get("/", include_in_schema=False)
def index() -> FileResponse:
    page = STATIC_DIR / "index.html"
    return FileResponse(page, media_type="text/html", headers={"Cache-Control": "no-cache"})


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


@router.post("/web/preview.png", response_class=Response, include_in_schema=False)
async def preview(request: Request, settings: SettingsDep) -> Response:
    """Render the uploaded mesh (multipart `file`) as the page's query thumbnail; nothing is stored."""
    form = await read_form(request, settings.max_upload_bytes)
    filename, data = form.file("file")
    png = await run_in_threadpool(_render, data, detect_format(filename), settings.max_vertices)
    return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})


def _render(data: bytes, file_type: str, max_vertices: int) -> bytes:
    mesh = load_upload(data, file_type, max_vertices)  # InvalidMeshError -> 422 (what an upload would get)
    if mesh.n_vertices > PREVIEW_MAX_VERTICES:
        mesh = simplify(mesh, PREVIEW_MAX_VERTICES)
    return render_png(mesh.vertices, mesh.faces, PREVIEW_SIZE)
