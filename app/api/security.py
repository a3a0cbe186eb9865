"""The web edge: security headers on every response, and no state change on behalf of another site.

Headers: a Content-Security-Policy that lets the page run its own scripts only (app/api/static, the
vendored three.js; /docs sets its own policy, which admits Swagger UI's one inline script by hash),
nosniff, no framing (frame-ancestors 'none' and X-Frame-Options DENY), no referrer.

A browser sends `Origin` with every POST, PUT, PATCH and DELETE; a page on another site that posts a form
to this service (it needs no CORS preflight for a multipart form) carries that site's origin and gets
403. Clients that send no Origin (curl, httpx, the CLI) and the service's own page pass (its host name,
whatever the port: a proxy such as deploy/nginx forwards `Host` without it); so do the origins named in
SHAPEBAG_CORS_ORIGINS.
"""

from __future__ import annotations

import base64
import hashlib
import re
from urllib.parse import urlsplit

from starlette.datastructures import Headers, MutableHeaders
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

PAGE_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:;"
    " connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'"
)
HEADERS = {
    "Content-Security-Policy": PAGE_CSP,
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Cross-Origin-Opener-Policy": "same-origin",
}
STATE_CHANGING = frozenset({"POST", "PUT", "PATCH", "DELETE"})
_SCHEMES = ("http", "https")
_INLINE_SCRIPT = re.compile(r"<script>(.*?)</script>", re.S)


def csp_with_inline_scripts(html: str) -> str:
    """PAGE_CSP, admitting exactly the inline <script> blocks of `html` by their SHA-256 (for /docs)."""
    hashes = [
        "'sha256-" + base64.b64encode(hashlib.sha256(s.encode()).digest()).decode() + "'"
        for s in _INLINE_SCRIPT.findall(html)
    ]
    return PAGE_CSP.replace("script-src 'self'", " ".join(["script-src 'self'", *hashes]))


def document_refusals(schema: dict) -> dict:
    """The OpenAPI schema with the 403 this middleware answers on every state-changing operation."""
    refusal = {
        "description": "Forbidden: sent by another site's page (a foreign Origin)",
        "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorResponse"}}},
    }
    for operations in schema.get("paths", {}).values():
        for method, operation in operations.items():
            if method.upper() in STATE_CHANGING:
                operation.setdefault("responses", {}).setdefault("403", refusal)
    return schema


def _hostname(netloc: str) -> str | None:
    """'Example.org:8080' -> 'example.org', '[::1]:80' -> '::1'; None when it is no host at all."""
    try:
        return urlsplit("//" + netloc.strip()).hostname
    except ValueError:
        return None


class SecureEdge:
    """ASGI middleware: HEADERS on every response (a route's own CSP wins), 403 for a state-changing
    request whose Origin is neither this host nor an allowed origin."""

    def __init__(self, app: ASGIApp, allowed_origins: list[str] | None = None) -> None:
        self.app = app
        self.allowed = {o.rstrip("/").lower() for o in allowed_origins or []}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if scope["method"] in STATE_CHANGING and not self._same_origin(Headers(scope=scope)):
            message = (
                "a state-changing request from another site's page is refused: send it from this"
                " service's own page, or from a client that sends no Origin header"
            )
            response = JSONResponse({"error": {"code": "cross_origin", "message": message}}, 403, HEADERS)
            await response(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                for name, value in HEADERS.items():
                    if name not in headers:
                        headers[name] = value
            await send(message)

        await self.app(scope, receive, send_with_headers)

    def _same_origin(self, headers: Headers) -> bool:
        origin = headers.get("origin")
        if origin is None:
            return True  # not a browser acting for a page: curl, httpx, the CLI
        if origin.rstrip("/").lower() in self.allowed:
            return True
        parts = urlsplit(origin)
        if parts.scheme not in _SCHEMES or not parts.netloc:
            return False  # 'null' (a sandboxed frame, a file: page) and anything odd
        # host names only: behind a TLS proxy the page is https and the request http, and a proxy may
        # forward Host without the port the page was served on
        own = _hostname(headers.get("host", ""))
        return own is not None and _hostname(parts.netloc) == own
