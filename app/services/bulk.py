"""Bulk ingestion of a folder of meshes through the same path as uploads (resumable: content-hash dedup)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from app.datasets.folder import read_mesh_folder
from app.services import ingestion
from app.services.context import ServiceContext
from app.storage import jobs as jobs_repo
from app.storage import vocabularies as vocab_repo


@dataclass
class BulkReport:
    submitted: int = 0  # new models queued
    existing: int = 0  # identical content already stored (skipped)
    rejected: list[tuple[Path, str]] = field(default_factory=list)  # refused before queueing
    job_ids: list[int] = field(default_factory=list)  # jobs to wait for (new and still pending)


def submit_folder(
    ctx: ServiceContext, directory: Path, on_file: Callable[[], None] = lambda: None
) -> BulkReport:
    """Queue every mesh of `directory`, labelled by its labels.csv where it has one (or unlabelled:
    datasets.folder.read_mesh_folder); re-running resumes where it stopped."""
    report = BulkReport()
    root = Path(directory).resolve()
    for item in read_mesh_folder(directory):
        try:
            data = item.path.read_bytes()
            where = item.path.relative_to(root).with_suffix("").as_posix()  # unlabelled: the folder tells
            name = f"{item.label}/{item.path.stem}" if item.label else where
            meta = {"source": item.path.name} | ({"split": item.split} if item.split else {})
            result = ingestion.submit(ctx, data, item.path.name, name=name, label=item.label, metadata=meta)
        except (OSError, ingestion.InvalidInputError) as exc:
            report.rejected.append((item.path, str(exc)))
            on_file()
            continue
        if result.created:
            report.submitted += 1
            report.job_ids.append(result.job_id)  # type: ignore[arg-type]
        else:
            report.existing += 1
            with ctx.db.read() as conn:  # a previous run's job may still be pending: wait for it too
                job = jobs_repo.latest_for_model(conn, result.model.id)
            if job is not None and job.state in ("queued", "running"):
                report.job_ids.append(job.id)
        on_file()
    return report


def wait_for_jobs(
    ctx: ServiceContext,
    job_ids: list[int],
    on_progress: Callable[[int, int], None] = lambda done, failed: None,
    poll_s: float = 0.3,
) -> tuple[int, int]:
    """Block until every job is done or failed; returns (done, failed)."""
    pending = set(job_ids)
    done = failed = 0
    while pending:
        with ctx.db.read() as conn:
            for jid in list(pending):
                job = jobs_repo.get(conn, jid)
                if job is None or job.state in ("done", "failed"):
                    pending.discard(jid)
                    if job is not None and job.state == "failed":
                        failed += 1
                    else:
                        done += 1
        on_progress(done, failed)
        if pending:
            time.sleep(poll_s)
    return done, failed


def ensure_vocabulary_job(ctx: ServiceContext) -> int | None:
    """With no active vocabulary, queue one fit on the ingested models (or return the pending one)."""
    with ctx.db.write() as conn:
        if vocab_repo.active(conn) is not None:
            return None
        pending = jobs_repo.pending(conn, "rebuild_vocabulary")
        if pending is not None:
            return pending.id
        return jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={})
