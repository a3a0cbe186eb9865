"""create_app(settings) and its lifespan: open storage, load vocabulary + index, start workers and pools."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.middleware.cors import CORSMiddleware

from app.api import errors
from app.api.client_budget import ClientBudget, document_client_bound
from app.api.deps import Runtime
from app.api.limits import GuardUploads, RefuseEncodedBodies, check_data_dir
from app.api.routes import admin, docs, explain, health, jobs, labels, models, search, variants, web
from app.api.security import SecureEdge, document_refusals
from app.config import Settings
from app.services import query_pool, vocabularies
from app.services.context import ServiceContext, open_context
from app.services.live_index import LiveIndex
from app.services.metrics import Metrics
from app.services.piece_budget import PieceBudget
from app.services.sweep import sweep_temp_files
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.worker.processes import WorkerPool

log = logging.getLogger("shapebag")


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()
    settings.check_secure()
    check_data_dir(settings.data_dir)  # a clear one-line refusal, not a traceback from the lifespan
    metrics = Metrics()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        ctx = await asyncio.to_thread(open_context, settings)
        await asyncio.to_thread(sweep_temp_files, ctx.data_dir)  # debris of writes cut short by a crash
        await asyncio.to_thread(vocabularies.ensure_default, ctx)
        live = LiveIndex(ctx)
        await asyncio.to_thread(live.refresh)
        workers = WorkerPool(ctx.settings, ctx.settings.workers)
        workers.start()
        describer = query_pool.from_settings(settings)
        await asyncio.to_thread(metrics.skip_history, ctx)
        if settings.warm_up:  # in the background: startup does not wait for it
            asyncio.get_running_loop().run_in_executor(None, describer.warm_up)
        pieces = PieceBudget(settings.piece_budget.concurrency, settings.piece_budget.queue,
                             settings.piece_budget.timeout_s)
        app.state.runtime = Runtime(ctx, live, describer, workers, metrics, pieces)
        poller = asyncio.create_task(_follow(ctx, live, workers))
        log.info("serving data dir %s: %s", ctx.data_dir, live.status())
        try:
            yield
        finally:
            poller.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await poller
            await asyncio.to_thread(workers.stop)
            await asyncio.to_thread(describer.close)
            await asyncio.to_thread(live.save)

    app = FastAPI(
        title="shapebag",
        version="0.1.0",
        description="Non-rigid 3D shape retrieval: Heat Kernel Signature + Bag of Features, L1 index.",
        lifespan=lifespan,
        docs_url=None,  # served by routes/docs.py from the package: FastAPI's default loads a CDN
        redoc_url=None,
    )
    app.state.settings = settings
    errors.install(app)
    app.add_middleware(RefuseEncodedBodies)  # 415 for gzip/deflate bodies: nothing is ever inflated
    app.add_middleware(  # 503 past N bodies being read at once, 408 after a stall
        GuardUploads, max_concurrent=settings.max_concurrent_uploads, timeout_s=settings.upload_timeout_s,
        min_rate=settings.upload_min_rate_kib_s * 1024, per_client=settings.client_uploads,
    )
    # outside the body guards (a refused client takes no upload slot), inside the edge (its 429s get the
    # security headers): names each request's client for the layers inside, answers its 429s
    tokens = {"api": settings.api_token, "admin": settings.admin_token}
    app.add_middleware(ClientBudget, max_requests=settings.client_requests, tokens=tokens)
    if settings.cors_origins:  # closed unless configured
        app.add_middleware(CORSMiddleware, allow_origins=settings.cors_origins, allow_methods=["GET", "POST"])
    # outside the others: its headers go on their refusals too, and a foreign Origin is refused first
    app.add_middleware(SecureEdge, allowed_origins=settings.cors_origins)

    @app.middleware("http")
    async def observe_latency(request: Request, call_next):
        t = time.perf_counter()
        response = await call_next(request)
        route = request.scope.get("route")
        path = getattr(route, "path", "unmatched")
        metrics.request_seconds.labels(request.method, path, str(response.status_code)).observe(
            time.perf_counter() - t
        )
        return response

    for module in (models, variants, labels, jobs, search, admin, health, web, docs, explain):
        app.include_router(module.router)
    generate = app.openapi

    def openapi() -> dict:
        if app.openapi_schema is None:
            app.openapi_schema = document_client_bound(document_refusals(generate()))
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return app


async def _follow(ctx: ServiceContext, live: LiveIndex, workers: WorkerPool) -> None:
    """Poll the database: new vectors/versions into the live index, periodic saves, first vocabulary;
    replace embedded workers that died."""
    s = ctx.settings
    while True:
        try:
            await asyncio.to_thread(live.refresh)
            if time.monotonic() - live.last_saved > s.index_save_interval_s:
                await asyncio.to_thread(live.save)
            if live.pair is None:
                await asyncio.to_thread(_maybe_fit_first_vocabulary, ctx)
            workers.replace_dead()
        except asyncio.CancelledError:
            raise
        except Exception:  # keep following; the next round retries
            log.exception("index follower failed")
        await asyncio.sleep(s.poll_interval_s)


def _maybe_fit_first_vocabulary(ctx: ServiceContext) -> None:
    """No vocabulary at all (none shipped): queue one fit once enough models are ready."""
    with ctx.db.read() as conn:
        if vocab_repo.all_versions(conn) or jobs_repo.pending(conn, "rebuild_vocabulary"):
            return
        ready = models_repo.count_by_status(conn)["ready"]
    if ready >= ctx.settings.auto_vocabulary_min_models:
        with ctx.db.write() as conn:
            if jobs_repo.pending(conn, "rebuild_vocabulary") is None:
                jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={})
                log.info("%d models ready and no vocabulary: queued a vocabulary fit", ready)
