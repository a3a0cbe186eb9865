"""Admin-side questions and requests: maintenance jobs, the active vocabulary, live workers."""

from __future__ import annotations

from app.services.context import ServiceContext
from app.storage import jobs as jobs_repo
from app.storage import vocabularies as vocab_repo
from app.storage.vocabularies import VocabularyRecord


def enqueue_once(ctx: ServiceContext, kind: str, payload: dict) -> tuple[int, str]:
    """(job id, state) of a maintenance job; one at a time: a pending one of that kind is returned."""
    with ctx.db.write() as conn:
        running = jobs_repo.pending(conn, kind)
        if running is not None:
            return running.id, running.state
        return jobs_repo.enqueue(conn, kind, payload=payload), "queued"


def vocabulary_versions(ctx: ServiceContext) -> tuple[VocabularyRecord | None, int]:
    """The active vocabulary version (None before the first) and how many versions exist."""
    with ctx.db.read() as conn:
        return vocab_repo.active(conn), len(vocab_repo.all_versions(conn))


def live_workers(ctx: ServiceContext) -> int:
    """Workers (embedded or `shapebag worker`) whose heartbeat is recent."""
    with ctx.db.read() as conn:
        return jobs_repo.live_workers(conn, within_s=max(10.0, ctx.settings.lease_seconds))
