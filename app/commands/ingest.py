"""`shapebag ingest DIR`: bulk-ingest a folder of meshes (labelled by its labels.csv, if any), resumable."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from app.cli import CommandError
from app.commands._common import add_data_dir, settings_from, setup_logging


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "ingest", help="ingest every mesh of a folder (labels from its labels.csv: file,class, if any)"
    )
    p.add_argument("directory", type=Path,
                   help="folder of meshes; with a labels.csv (file,class) only the files it lists, labelled "
                   "where the class is filled in; without one, every mesh file under it, unlabelled")
    add_data_dir(p)
    p.add_argument("--processes", type=int, default=None, help="local worker processes (default: cores)")
    p.add_argument("--no-wait", action="store_true", help="only queue the jobs (a server's workers run them)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    setup_logging()
    settings = settings_from(args)
    report = ingest_folder(
        settings, args.directory, args.processes or os.cpu_count() or 1, wait=not args.no_wait
    )
    return 1 if report["failed"] or report["rejected"] else 0


def ingest_folder(settings, directory: Path, processes: int, wait: bool = True) -> dict:
    """Queue the folder, run local workers until its jobs finish, fit a first vocabulary if none."""
    from app.datasets.folder import DatasetError, read_mesh_folder
    from app.progress import progress
    from app.services import bulk, vocabularies
    from app.services.context import open_context
    from app.worker.processes import WorkerPool

    try:
        items = read_mesh_folder(directory)
    except DatasetError as exc:
        raise CommandError(str(exc)) from exc
    total = len(items)
    unlabelled = sum(item.label is None for item in items)
    if unlabelled:
        print(f"{unlabelled} of {total} meshes have no label"
              + ("" if (Path(directory) / "labels.csv").is_file() else " (no labels.csv)"))
    ctx = open_context(settings)
    vocabularies.ensure_default(ctx)  # as the server does: the shipped vocabulary, not a fit on this folder
    with progress(total=total, desc="queue", unit="mesh") as bar:
        report = bulk.submit_folder(ctx, directory, on_file=lambda: bar.update(1))
    for path, reason in report.rejected:
        print(f"  rejected {path}: {reason}")
    print(f"{report.submitted} new, {report.existing} already stored, {len(report.rejected)} rejected")
    summary = {
        "new": report.submitted,
        "existing": report.existing,
        "rejected": len(report.rejected),
        "failed": 0,
    }
    if not wait:
        return summary
    quiet = ctx.settings.model_copy(update={"log_level": "WARNING"})  # keep the progress bars readable
    pool = WorkerPool(quiet, max(1, processes), prefix="ingest")
    pool.start()
    try:
        with progress(total=len(report.job_ids), desc="describe", unit="mesh") as bar:

            def on_progress(done: int, failed: int) -> None:
                if bar.n == done + failed:
                    return
                bar.n = done + failed
                bar.set_postfix(failed=failed)
                bar.refresh()

            _, summary["failed"] = bulk.wait_for_jobs(ctx, report.job_ids, on_progress)
        vocab_job = bulk.ensure_vocabulary_job(ctx)
        if vocab_job is not None:
            print("no active vocabulary: fitting one on the ingested models ...")
            _, failed = bulk.wait_for_jobs(ctx, [vocab_job])
            if failed:
                print("  the vocabulary fit failed: see `shapebag vocabulary show`")
    finally:
        pool.stop()
    if summary["failed"]:
        print(f"{summary['failed']} meshes failed (their reasons: GET /models?status=failed)")
    return summary
