"""FastAPI dependencies as Annotated aliases; the admin guard."""

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
