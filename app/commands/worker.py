"""`shapebag worker`: more ingestion processes against an existing data directory."""

from __future__ import annotations

import argparse
import signal
import threading

from app.cli import CommandError
from app.commands._common import add_data_dir, settings_from, setup_logging


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("worker", help="run ingestion/rebuild jobs from the data directory's queue")
    add_data_dir(p)
    p.add_argument("--processes", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--exit-when-idle", action="store_true", help="stop once the queue is empty")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from app.worker.processes import WorkerPool, pin_threads

    setup_logging(verbose=True)
    settings = settings_from(args)
    if args.processes <= 1 or args.exit_when_idle:
        pin_threads()
        from app.services.context import open_context
        from app.worker.runner import Worker

        stop = threading.Event()
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        try:
            ctx = open_context(settings)
        except OSError as exc:  # one line, like `shapebag serve`, not a traceback
            why = exc.strerror or exc
            raise CommandError(f"cannot use the data directory {settings.data_dir}: {why}") from exc
        worker = Worker(ctx)
        print(f"shapebag worker {worker.name}: {settings.data_dir}")
        try:
            n = worker.run_forever(stop, exit_when_idle=args.exit_when_idle)
        except KeyboardInterrupt:
            return 130
        print(f"shapebag worker: {n} jobs run")
        return 0
    pool = WorkerPool(settings, args.processes, prefix="worker")
    pool.start()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        while not stop.wait(1.0):
            if pool.replace_dead():  # e.g. one ended past an ingest job's time limit
                print("shapebag worker: a worker process died; started a new one")
    except KeyboardInterrupt:
        pass
    pool.stop()
    return 0
