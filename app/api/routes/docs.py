"""GET /docs from the package, and the vendored third-party assets under /static/vendor/.

FastAPI's default /docs page loads Swagger UI from a CDN: a blank page without internet. Here the page
(FastAPI's own template) points at the copy of swagger-ui-dist vendored in app/api/static/vendor/
(update.sh there re-vendors it, and three.js for the viewer, from npm). ReDoc is off: it is CDN-only too.
"""

from __future__ import annotations

import functools
import mimetypes
from pathlib import Path

from fastapi import APIRouter, Request
from fastapi.openapi.docs import get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.responses import FileResponse, HTMLResponse

from app.api.security import csp_with_inline_scripts
from app.services.errors import NotFoundError

router = APIRouter(include_in_schema=False)
VENDOR_DIR = Path(__file__).resolve().parent.parent / "static" / "vendor"
VENDOR_URL = "/static/vendor"
SERVED = (".js", ".css", ".png")  # never update.sh or the licence texts' odd names as scripts
OAUTH2_REDIRECT = "/docs/oauth2-redirect"


@router.get("/docs")
def swagger_ui(request: Request) -> HTMLResponse:
    app = request.app
    return _with_csp(
        get_swagger_ui_html(
            openapi_url=app.openapi_url,
            title=f"{app.title} · API docs",
            swagger_js_url=f"{VENDOR_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{VENDOR_URL}/swagger-ui.css",
            swagger_favicon_url=f"{VENDOR_URL}/favicon-32x32.png",
            oauth2_redirect_url=OAUTH2_REDIRECT,
        )
    )


@router.get(OAUTH2_REDIRECT)
def swagger_ui_redirect() -> HTMLResponse:
    return _with_csp(get_swagger_ui_oauth2_redirect_html())


def _with_csp(page: HTMLResponse) -> HTMLResponse:
    """The page's policy, admitting its own inline script (Swagger UI's start-up call) by hash."""
    page.headers["Content-Security-Policy"] = csp_with_inline_scripts(bytes(page.body).decode())
    return page


@functools.cache
def _vendor_names() -> frozenset[str]:
    return frozenset(p.name for p in VENDOR_DIR.iterdir() if p.is_file() and p.suffix in SERVED)


@router.get(VENDOR_URL + "/{name}")
def vendor_asset(name: str) -> FileResponse:
    """One flat directory of vendored files; only names listed from it (no path tricks), else 404."""
    if name not in _vendor_names():
        raise NotFoundError(f"no vendored file {name[:100]!r}")
    path = VENDOR_DIR / name
    media = mimetypes.guess_type(path.name)[0] or "application/octet-stream"
    if path.suffix == ".js":
        media = "text/javascript"  # some systems map .js to application/x-javascript; modules need this
    # pinned versions (update.sh): a day's caching spares the 1.7 MB bundle on every /docs visit
    return FileResponse(path, media_type=media, headers={"Cache-Control": "public, max-age=86400"})
