"""Domain errors -> HTTP, in one place. Every error body is {"error": {"code", "message"}}."""

from __future__ import annotations

import errno
import logging
import sqlite3
from collections.abc import Mapping

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect
from starlette.routing import Match

from app.api.security import HEADERS as SECURITY_HEADERS
from app.core.mesh import InvalidMeshError, UnsupportedFormatError
from app.services import errors as e

log = logging.getLogger(__name__)

STATUS: dict[type[e.ServiceError], int] = {
    e.NotFoundError: 404,
    e.InvalidInputError: 422,
    e.PayloadTooLargeError: 413,
    e.QueueFullError: 503,
    e.NotReadyError: 503,
    e.ConflictError: 409,
    e.DescribeTimeoutError: 504,
    e.DescribeCrashedError: 503,
    e.InsufficientStorageError: 507,
}
RETRY_AFTER_S = 5
HTTP_CODES = {401: "unauthorized", 404: "not_found", 405: "method_not_allowed", 413: "payload_too_large"}


class AdminAuthError(e.ServiceError):
    code = "unauthorized"


STATUS[AdminAuthError] = 401


def error_response(
    status: int, code: str, message: str, headers: Mapping[str, str] | None = None
) -> JSONResponse:
    return JSONResponse({"error": {"code": code, "message": message}}, status_code=status, headers=headers)


def _allowed_methods(request: Request) -> str:
    """Every method some route serves at this path: Starlette's own Allow names the first matching
    route's methods only (POST for /models, which GET serves too)."""
    routes = request.app.router.routes
    allowed = [
        m
        for m in ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE")
        if any(r.matches({**request.scope, "method": m})[0] == Match.FULL for r in routes)
    ]
    return ", ".join(allowed)


def install(app: FastAPI) -> None:
    @app.exception_handler(e.ServiceError)
    async def _service(request: Request, exc: e.ServiceError) -> JSONResponse:
        status = next((s for cls, s in STATUS.items() if isinstance(exc, cls)), 500)
        headers = {"WWW-Authenticate": "X-Admin-Token"} if status == 401 else None
        if status in (429, 503):  # a full queue or a restarting pool: tell clients when to come back
            headers = {"Retry-After": str(RETRY_AFTER_S)}
        return error_response(status, exc.code, exc.message, headers)

    @app.exception_handler(InvalidMeshError)
    async def _mesh(request: Request, exc: InvalidMeshError) -> JSONResponse:
        return error_response(422, "invalid_mesh", str(exc))

    # a subclass of InvalidMeshError: Starlette picks the handler of the most specific class, so a format
    # shapebag does not read is 415 on every door (/models, /search, /web/preview.png), named and with
    # what to convert to; a file in a supported format that is broken stays 422 invalid_mesh
    @app.exception_handler(UnsupportedFormatError)
    async def _format(request: Request, exc: UnsupportedFormatError) -> JSONResponse:
        return error_response(415, "unsupported_format", str(exc))

    @app.exception_handler(ClientDisconnect)
    async def _gone(request: Request, exc: ClientDisconnect) -> JSONResponse:
        """The client closed its connection while its body was read: nothing to answer, and no
        error of the server's. One line at INFO, no traceback (a client aborting uploads in a loop
        wrote 2.4 MB/s of tracebacks as unhandled 500s; red team, 2026-12-05)."""
        log.info("client went away during %s %s", request.method, request.url.path)
        return error_response(400, "client_disconnected", "the connection closed before the body was read")

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        first = exc.errors()[0] if exc.errors() else {}
        where = ".".join(str(p) for p in first.get("loc", ()))
        return error_response(422, "invalid_request", f"{where}: {first.get('msg', 'invalid request')}")

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        code = HTTP_CODES.get(exc.status_code, "http_error")
        headers = dict(exc.headers or {})
        if exc.status_code == 405:
            headers["Allow"] = _allowed_methods(request)
        return error_response(exc.status_code, code, str(exc.detail), headers)

    @app.exception_handler(OSError)
    async def _storage(request: Request, exc: OSError) -> JSONResponse:
        """A full or read-only data directory is the operator's problem, said plainly; never a 500."""
        log.error("storage error on %s %s: %s", request.method, request.url.path, exc)
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            return error_response(507, "insufficient_storage", "the server's disk is full; nothing was saved")
        if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
            return error_response(
                503, "storage_unavailable", "the server cannot write its data directory; nothing was saved",
                {"Retry-After": str(RETRY_AFTER_S)},
            )
        log.exception("unhandled OS error")
        return error_response(500, "internal_error", "internal error; see the server log")

    try:  # the PostgreSQL backend (an optional extra): its "disk full", SQLSTATE 53100
        from psycopg.errors import DiskFull

        @app.exception_handler(DiskFull)
        async def _postgres_full(request: Request, exc: Exception) -> JSONResponse:
            log.error("database storage error on %s %s: %s", request.method, request.url.path, exc)
            return error_response(507, "insufficient_storage", "the server's disk is full; nothing was saved")
    except ImportError:
        pass

    @app.exception_handler(sqlite3.OperationalError)
    async def _database(request: Request, exc: sqlite3.OperationalError) -> JSONResponse:
        """SQLite's "database or disk is full" (SQLITE_FULL) is no OSError: the same 507 as ENOSPC."""
        if "disk is full" in str(exc):
            log.error("database storage error on %s %s: %s", request.method, request.url.path, exc)
            return error_response(507, "insufficient_storage", "the server's disk is full; nothing was saved")
        log.exception("unhandled database error on %s %s", request.method, request.url.path)
        return error_response(500, "internal_error", "internal error; see the server log", SECURITY_HEADERS)

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        # answered outside the middleware stack (Starlette's ServerErrorMiddleware): headers set here
        return error_response(500, "internal_error", "internal error; see the server log", SECURITY_HEADERS)
