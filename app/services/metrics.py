"""Prometheus metrics of one app instance (its own registry, so several apps can live in one process)."""

from __future__ import annotations

import json
import sqlite3
import threading

from prometheus_client import CollectorRegistry, Gauge, Histogram, generate_latest

from app.services.context import ServiceContext
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo

LATENCY_BUCKETS = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30)


class Metrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.request_seconds = Histogram(
            "shapebag_request_seconds",
            "HTTP request latency",
            ["method", "route", "status"],
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.describe_seconds = Histogram(
            "shapebag_describe_seconds",
            "time to describe one mesh (load + spectrum + HKS + keypoints)",
            ["where"],
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.queue_depth = Gauge(
            "shapebag_queue_depth", "jobs waiting or running", ["state"], registry=self.registry
        )
        self.models = Gauge("shapebag_models", "models by status", ["status"], registry=self.registry)
        self.indexed = Gauge("shapebag_indexed_models", "vectors in the active index", registry=self.registry)
        self._cursor = 0  # every ingest job with id <= cursor has been observed
        self._observed: set[int] = set()  # finished jobs past the cursor already observed
        self._lock = threading.Lock()  # scrapes may overlap

    def skip_history(self, ctx: ServiceContext) -> None:
        """Count only jobs that finish from now on (the histogram covers this process's lifetime)."""
        with ctx.db.read() as conn:
            self._follow_jobs(conn, observe=False)

    def render(self, ctx: ServiceContext, indexed: int) -> bytes:
        """Refresh the gauges from the database, then render the text exposition format."""
        with ctx.db.read() as conn:
            for state, n in jobs_repo.queue_depth(conn).items():
                self.queue_depth.labels(state).set(n)
            for status, n in models_repo.count_by_status(conn).items():
                self.models.labels(status).set(n)
            self._follow_jobs(conn, observe=True)
        self.indexed.set(indexed)
        return generate_latest(self.registry)

    def _follow_jobs(self, conn: sqlite3.Connection, observe: bool) -> None:
        """Observe the describe time of ingest jobs finished since the last call (any order)."""
        with self._lock:
            self._follow_jobs_locked(conn, observe)

    def _follow_jobs_locked(self, conn: sqlite3.Connection, observe: bool) -> None:
        rows = conn.execute(
            "SELECT id, state, timings FROM jobs WHERE kind = 'ingest' AND id > ? ORDER BY id",
            (self._cursor,),
        ).fetchall()
        contiguous = True
        for row in rows:
            finished = row["state"] in ("done", "failed")
            if finished and row["id"] not in self._observed:
                self._observed.add(row["id"])
                t = json.loads(row["timings"] or "{}")
                spent = sum(v for k, v in t.items() if k == "load" or k.startswith("describe."))
                if observe and row["state"] == "done" and spent:
                    self.describe_seconds.labels("ingest").observe(spent)
            contiguous = contiguous and finished
            if contiguous:  # every job up to here is finished: move the cursor, forget them
                self._cursor = row["id"]
                self._observed.discard(row["id"])
