"""FastAPI dependencies as Annotated aliases; the doors (admin token, optional write token).

Which token opens what (docs/reliability.md, "The doors"):
- reads (GET, POST /search, the web page): open;
- POST /models: open while SHAPEBAG_API_TOKEN is unset; once set, that token or the admin token;
- DELETE /models/{id}: the API token (when set) or the admin token, never open;
- /admin/*: the admin token only.
"""

from __future__ import annotations

import hmac
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Header, Request

from app.api.errors import AdminAuthError
from app.config import Settings
from app.services.context import ServiceContext
from app.services.live_index import LiveIndex
from app.services.metrics import Metrics
from app.services.piece_budget import PieceBudget
from app.services.query_pool import QueryDescriber
from app.worker.processes import WorkerPool


@dataclass
class Runtime:
    """Everything the lifespan opens and the routes use."""

    ctx: ServiceContext
    live: LiveIndex
    describer: QueryDescriber
    workers: WorkerPool
    metrics: Metrics
    pieces: PieceBudget  # the pieces matched at once in this process, and who waits


def get_runtime(request: Request) -> Runtime:
    return request.app.state.runtime


def get_ctx(runtime: Annotated[Runtime, Depends(get_runtime)]) -> ServiceContext:
    return runtime.ctx


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


RuntimeDep = Annotated[Runtime, Depends(get_runtime)]
CtxDep = Annotated[ServiceContext, Depends(get_ctx)]
SettingsDep = Annotated[Settings, Depends(get_settings)]


def require_admin(
    settings: SettingsDep,
    x_admin_token: Annotated[str | None, Header(description="the SHAPEBAG_ADMIN_TOKEN secret")] = None,
) -> None:
    """401 unless the X-Admin-Token header matches (constant-time compare)."""
    if x_admin_token is None or not hmac.compare_digest(
        x_admin_token.encode("utf-8"), settings.admin_token.encode("utf-8")
    ):
        raise AdminAuthError("admin routes need the X-Admin-Token header with the configured token")


AdminDep = Annotated[None, Depends(require_admin)]

AdminHeader = Annotated[str | None, Header(description="the SHAPEBAG_ADMIN_TOKEN secret")]
ApiHeader = Annotated[str | None, Header(description="the SHAPEBAG_API_TOKEN secret")]
BearerHeader = Annotated[
    str | None, Header(description="Bearer <SHAPEBAG_API_TOKEN or SHAPEBAG_ADMIN_TOKEN>")
]


def _same(given: str | None, secret: str) -> bool:
    return bool(given) and bool(secret) and hmac.compare_digest(given.encode("utf-8"), secret.encode("utf-8"))  # type: ignore[union-attr]


def _writer(
    settings: Settings, authorization: str | None, x_api_token: str | None, x_admin_token: str | None
) -> bool:
    """True when a header carries the API token (if one is set) or the admin token."""
    bearer = None
    if authorization and authorization[:7].lower() == "bearer ":
        bearer = authorization[7:].strip()
    if _same(x_admin_token, settings.admin_token) or _same(bearer, settings.admin_token):
        return True
    return bool(settings.api_token) and (
        _same(x_api_token, settings.api_token) or _same(bearer, settings.api_token)
    )


def require_upload(
    settings: SettingsDep,
    authorization: BearerHeader = None,
    x_api_token: ApiHeader = None,
    x_admin_token: AdminHeader = None,
) -> None:
    """POST /models: open unless SHAPEBAG_API_TOKEN is set; then that token or the admin token."""
    if settings.api_token and not _writer(settings, authorization, x_api_token, x_admin_token):
        raise AdminAuthError("uploads need the API token: 'Authorization: Bearer <token>' or 'X-API-Token'")


def require_delete(
    settings: SettingsDep,
    authorization: BearerHeader = None,
    x_api_token: ApiHeader = None,
    x_admin_token: AdminHeader = None,
) -> None:
    """DELETE /models/{id}: the API token (when set) or the admin token; never open."""
    if not _writer(settings, authorization, x_api_token, x_admin_token):
        which = (
            "the API token or the admin token" if settings.api_token else "the admin token (X-Admin-Token)"
        )
        raise AdminAuthError(f"deleting a model needs {which}")


UploadDep = Annotated[None, Depends(require_upload)]
DeleteDep = Annotated[None, Depends(require_delete)]
