"""/healthz (the process answers), /readyz (it can serve searches), /metrics (Prometheus)."""

from __future__ import annotations

from fastapi import APIRouter, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse
from prometheus_client import CONTENT_TYPE_LATEST

from app.api.deps import RuntimeDep
from app.api.schemas import Health, Readiness
from app.services import maintenance

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Health)
def healthz() -> Health:
    return Health(status="ok")


@router.get("/readyz", response_model=Readiness, responses={503: {"model": Readiness}})
def readyz(runtime: RuntimeDep) -> JSONResponse:
    """Vocabulary and index loaded, database reachable, workers alive; 503 otherwise (checks say which)."""
    checks: dict = {"database": runtime.ctx.db.ping()}
    live = runtime.live.status()
    checks["vocabulary"] = live["vocabulary_id"] is not None
    checks["index"] = live["vocabulary_id"] is not None
    checks["indexed_models"] = live["indexed"]
    if not checks["vocabulary"]:
        checks["hint"] = "no vocabulary yet: POST /admin/vocabulary/rebuild once models are ingested"
    embedded = runtime.workers.count
    if embedded:
        checks["workers"] = runtime.workers.alive() == embedded
        checks["workers_alive"] = runtime.workers.alive()
    else:  # workers run elsewhere (`shapebag worker`): trust their heartbeats
        n = maintenance.live_workers(runtime.ctx)
        checks["workers"] = n > 0
        checks["workers_alive"] = n
    ready = all(checks[k] for k in ("database", "vocabulary", "index", "workers"))
    return JSONResponse(Readiness(ready=ready, checks=checks).model_dump(), status_code=200 if ready else 503)


@router.get("/metrics", response_class=Response)
async def metrics(runtime: RuntimeDep) -> Response:
    body = await run_in_threadpool(runtime.metrics.render, runtime.ctx, runtime.live.status()["indexed"])
    return Response(body, media_type=CONTENT_TYPE_LATEST)
