"""The collection's own vocabulary: queue a background refit once the collection is large enough.

With SHAPEBAG_VOCABULARY_REFIT_AT=N, a worker that finishes an ingest (or starts) checks the collection:
at N ready models, and again each time it has doubled since the last fit on it, it queues one
rebuild_vocabulary job, the admin rebuild's job (rebuild_vocabulary in vocabularies.py: fit on the stored
descriptions, re-encode every model, swap vocabulary and index in one transaction). Searches answer from
the old pair until the swap; a refit that fails leaves the old pair serving and is not retried until the
collection has doubled again.
"""

from __future__ import annotations

import logging

from app.services.context import ServiceContext
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.storage.jobs import JobRecord
from app.storage.vocabularies import VocabularyRecord

log = logging.getLogger(__name__)
KIND = "rebuild_vocabulary"
TRIGGER = "collection"  # payload["trigger"] of the jobs queued here (admin rebuilds have none)


def refit_due_at(threshold: int, fitted_on: int, failed_at: int = 0) -> int | None:
    """Ready models at which the next refit is due (None: refits are off, threshold 0).

    threshold: SHAPEBAG_VOCABULARY_REFIT_AT; fitted_on: models the active vocabulary was fit on (0 for
    one not fit on this collection, such as the shipped one); failed_at: models when the last automatic
    refit was queued, if it failed (0 otherwise). First at `threshold`, then at twice the last fit or
    failed attempt: a collection refits O(log n) times, and a failing refit is not retried every ingest.
    """
    if threshold <= 0:
        return None
    last = max(fitted_on, failed_at)
    return max(threshold, 2 * last) if last > 0 else threshold


def fitted_on(record: VocabularyRecord | None) -> int:
    """Models of this collection the version was fit on (rebuild_vocabulary records it at register);
    0 for a version fit elsewhere, such as the shipped one."""
    if record is None:
        return 0
    models = record.metadata.get("collection_models")
    return int(models) if isinstance(models, int | float) else 0


def failed_at(last: JobRecord | None) -> int:
    """Collection size of the last rebuild job if it was an automatic refit that failed, else 0."""
    if last is None or last.state != "failed" or last.payload.get("trigger") != TRIGGER:
        return 0
    return int(last.payload.get("collection") or 0)


def queue_refit_if_due(ctx: ServiceContext) -> int | None:
    """Queue a refit of the vocabulary on the collection when one is due; returns the new job's id.

    Nothing happens with refits off, before any vocabulary (the first fit is
    SHAPEBAG_AUTO_VOCABULARY_MIN_MODELS'), or while any vocabulary rebuild is queued or running: the
    check and the enqueue share one write transaction, so two workers never queue two refits.
    """
    threshold = ctx.settings.vocabulary_refit_at
    if threshold <= 0:
        return None
    with ctx.db.read() as conn:  # the cheap check first: it runs after every ingest
        ready = models_repo.count_by_status(conn)["ready"]
        active = vocab_repo.active(conn)
    due = refit_due_at(threshold, fitted_on(active))
    if active is None or due is None or ready < due:
        return None
    with ctx.db.write() as conn:
        if jobs_repo.pending(conn, KIND) is not None:
            return None
        active = vocab_repo.active(conn)
        due = refit_due_at(threshold, fitted_on(active), failed_at(jobs_repo.latest(conn, KIND)))
        if active is None or due is None or ready < due:
            return None
        job_id = jobs_repo.enqueue(conn, KIND, payload={"trigger": TRIGGER, "collection": ready})
    log.info("%d models ready (refit due at %d): queued vocabulary refit job %d on the collection",
             ready, due, job_id)
    return job_id


def refit_status(ctx: ServiceContext) -> tuple[int, int | None]:
    """(ready models now, ready models at which the next refit is due; None: refits are off)."""
    with ctx.db.read() as conn:
        ready = models_repo.count_by_status(conn)["ready"]
        active = vocab_repo.active(conn)
        last = jobs_repo.latest(conn, KIND)
    return ready, refit_due_at(ctx.settings.vocabulary_refit_at, fitted_on(active), failed_at(last))
