"""Job runner: claim a job with a lease, run it, keep the lease alive, retry or give up with the reason."""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
import traceback
from collections.abc import Callable

from app.core.mesh import InvalidMeshError
from app.services import ingestion, refit, vocabularies
from app.services.context import ServiceContext
from app.services.errors import InvalidInputError
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage.jobs import JobRecord
from app.worker.deadline import JobTimeout, wall_clock_limit

log = logging.getLogger(__name__)

# errors that no retry can fix: the job fails at once with the message
PERMANENT = (InvalidMeshError, InvalidInputError)


def default_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


class Worker:
    def __init__(self, ctx: ServiceContext, name: str | None = None, hard_deadline: bool = False) -> None:
        """hard_deadline: end this process when an ingest job cannot be stopped cleanly at its limit
        (for processes a WorkerPool replaces; worker/deadline.py)."""
        self.ctx = ctx
        self.name = name or default_name()
        self.hard_deadline = hard_deadline
        self._handlers: dict[str, Callable[[JobRecord, Callable[[], None]], object]] = {
            "ingest": lambda job, keep: ingestion.run_ingest(ctx, job),
            "rebuild_vocabulary": lambda job, keep: vocabularies.rebuild_vocabulary(
                ctx, job.id, job.payload, keep
            ),
            "rebuild_index": lambda job, keep: vocabularies.reencode_active(ctx, job.id),
        }

    def run_once(self) -> JobRecord | None:
        """Claim and run one job; returns it (None when the queue is empty)."""
        s = self.ctx.settings
        job = jobs_repo.claim(self.ctx.db, self.name, s.lease_seconds, s.max_attempts)
        if job is None:
            return None
        log.info("%s: job %d (%s) attempt %d", self.name, job.id, job.kind, job.attempts)
        stop = threading.Event()
        keeper = threading.Thread(target=self._keep_lease, args=(job.id, stop), daemon=True)
        keeper.start()
        try:
            self._run(job)
        except JobTimeout:  # not retried: the same mesh would take as long again
            self._fail(job, self._overrun(job))
        except PERMANENT as exc:
            self._fail(job, str(exc))
        except MemoryError:  # RLIMIT_AS (SHAPEBAG_WORKER_MEMORY_MB): the same input would hit it again
            limit = s.worker_memory_mb
            self._fail(job, f"the job needs more memory than the worker limit of {limit} MB")
        except Exception as exc:  # a bug or a transient fault: retry while attempts remain
            log.error("job %d failed: %s", job.id, traceback.format_exc())
            reason = f"{type(exc).__name__}: {exc}"
            if job.attempts < s.max_attempts:
                with self.ctx.db.write() as conn:
                    jobs_repo.release_for_retry(conn, job.id, reason)
            else:
                self._fail(job, f"gave up after {job.attempts} attempts: {reason}")
        else:
            if job.kind == "ingest":  # one more model: the collection may now call for its own vocabulary
                self._queue_refit()
        finally:
            stop.set()
            keeper.join()
        return job

    def _run(self, job: JobRecord) -> None:
        if job.kind != "ingest":  # maintenance jobs (vocabulary fits) may rightly take long
            self._handlers[job.kind](job, lambda: None)
            return
        hard = (lambda: self._fail(job, self._overrun(job))) if self.hard_deadline else None
        with wall_clock_limit(self.ctx.settings.ingest_timeout_s, on_hard=hard):
            self._handlers[job.kind](job, lambda: None)

    def _queue_refit(self) -> None:
        """Queue a refit of the vocabulary on the collection if one is due (services/refit.py); a failed
        check is logged and never fails the job that ran before it."""
        try:
            refit.queue_refit_if_due(self.ctx)
        except Exception:
            log.exception("could not check whether a vocabulary refit is due")

    def _overrun(self, job: JobRecord) -> str:
        limit = self.ctx.settings.ingest_timeout_s
        return (
            f"ingestion took longer than the limit of {limit:g} s (SHAPEBAG_INGEST_TIMEOUT_S): the mesh"
            " is too costly to describe; send a simpler or smaller one"
        )

    def _fail(self, job: JobRecord, reason: str) -> None:
        with self.ctx.db.write() as conn:
            jobs_repo.mark_failed(conn, job.id, reason)
            if job.model_id is not None:
                models_repo.set_failed(conn, job.model_id, reason)

    def _keep_lease(self, job_id: int, stop: threading.Event) -> None:
        """Extend the lease while the job runs, and beat the heartbeat: only a dead worker's job expires."""
        interval = max(0.5, self.ctx.settings.lease_seconds / 3)
        while not stop.wait(interval):
            try:
                jobs_repo.extend_lease(self.ctx.db, job_id, self.name, self.ctx.settings.lease_seconds)
                jobs_repo.heartbeat(self.ctx.db, self.name, os.getpid())
            except Exception:  # the next beat retries; a lost lease only means a duplicate run
                log.warning("could not extend the lease of job %d", job_id)

    def run_forever(
        self, stop: threading.Event | None = None, idle_sleep_s: float = 0.2, exit_when_idle: bool = False
    ) -> int:
        """Work until `stop` is set (or the queue is empty, with exit_when_idle); returns jobs run."""
        stop = stop or threading.Event()
        done = 0
        last_beat = 0.0
        self._queue_refit()  # a collection already past the threshold when refits were turned on
        while not stop.is_set():
            if time.monotonic() - last_beat > 2.0:
                jobs_repo.heartbeat(self.ctx.db, self.name, os.getpid())
                last_beat = time.monotonic()
            job = self.run_once()
            if job is not None:
                done += 1
                continue
            if exit_when_idle:
                break
            stop.wait(idle_sleep_s)
        jobs_repo.forget_worker(self.ctx.db, self.name)
        return done
