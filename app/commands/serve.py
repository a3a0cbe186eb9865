"""`shapebag serve`: the REST API (and its embedded workers) with uvicorn.

`--processes N` runs N API processes on one port (uvicorn's workers, each calling
app.main:create_app): each holds its own live index and follows the database through the same poll as
API replicas on other hosts, on SQLite (one data directory, WAL) as on PostgreSQL. The equivalent
by hand: `uvicorn --factory app.main:create_app --workers N` with the settings in SHAPEBAG_* variables.
"""

from __future__ import annotations

import argparse
import os
import socket

from app.cli import CommandError
from app.commands._common import add_data_dir, settings_from, setup_logging


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("serve", help="serve the REST API and the web page")
    add_data_dir(p)
    p.add_argument("--host", default=None, help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="port (default 8000)")
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="embedded ingestion processes, per API process (default: cores / --processes)",
    )
    p.add_argument(
        "--processes",
        type=int,
        default=1,
        help="API processes sharing the port (uvicorn workers), each with its live index (default 1)",
    )
    p.add_argument("--dev", action="store_true", help="dev mode: allows the default admin token")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.processes < 1:
        raise CommandError(f"--processes must be at least 1, not {args.processes}")
    workers = args.workers
    if workers is None and args.processes > 1:  # the cores shared between the API processes
        workers = max(1, (os.cpu_count() or 1) // args.processes)
    try:
        settings = settings_from(
            args, host=args.host, port=args.port, workers=workers, dev_mode=True if args.dev else None
        )
    except ValueError as exc:
        raise CommandError(str(exc)) from exc
    return serve(settings, processes=args.processes)


def check_port_free(host: str, port: int) -> None:
    """Refuse a port that is taken now, before the seconds of start-up: uvicorn binds only after the
    lifespan has opened storage, loaded the index and started workers. Bound as uvicorn binds
    (SO_REUSEADDR), so a port left in TIME_WAIT by a previous run is not reported as taken."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as exc:
            raise CommandError(
                f"cannot listen on {host}:{port}: {exc.strerror or exc} (another server there? "
                "stop it, or choose another port with --port or SHAPEBAG_PORT)"
            ) from exc


def serve(settings, processes: int = 1) -> int:
    import uvicorn

    from app.api.header_deadline import HeaderDeadlineProtocol
    from app.config import DEFAULT_ADMIN_TOKEN
    from app.main import create_app

    check_port_free(settings.host, settings.port)
    setup_logging(verbose=True)
    try:
        app = create_app(settings)
    except ValueError as exc:  # e.g. the default admin token outside dev mode
        raise CommandError(str(exc)) from exc
    print(f"shapebag: serving {settings.data_dir} on http://{settings.host}:{settings.port}/ (docs at /docs)")
    if settings.dev_mode and settings.admin_token == DEFAULT_ADMIN_TOKEN:  # the README's admin calls need it
        token = DEFAULT_ADMIN_TOKEN
        print(f"shapebag: dev mode, admin token {token!r}: curl -H 'X-Admin-Token: {token}' ...")
    os.environ["SHAPEBAG_HEADER_TIMEOUT_S"] = str(settings.header_timeout_s)  # read by the protocol
    # X-Forwarded-For is believed only from the proxy named (uvicorn's own default trusts 127.0.0.1)
    trusted = settings.forwarded_allow_ips.strip()
    proxy: dict = {"proxy_headers": bool(trusted), "forwarded_allow_ips": trusted or None}
    if processes == 1:
        uvicorn.run(app, host=settings.host, port=settings.port, log_level="info",
                    http=HeaderDeadlineProtocol, **proxy)
        return 0
    # uvicorn starts each process from an import string (an app object cannot cross a process start):
    # the factory rebuilds Settings from the environment, so the flags travel as SHAPEBAG_* variables
    os.environ.update(
        SHAPEBAG_DATA_DIR=str(settings.data_dir),
        SHAPEBAG_HOST=settings.host,
        SHAPEBAG_PORT=str(settings.port),
        SHAPEBAG_WORKERS=str(settings.workers),
        SHAPEBAG_DEV_MODE="true" if settings.dev_mode else "false",
    )
    print(f"shapebag: {processes} API processes, each with its own live index and {settings.workers} workers")
    uvicorn.run(
        "app.main:create_app",
        factory=True,
        workers=processes,
        host=settings.host,
        port=settings.port,
        log_level="info",
        http=HeaderDeadlineProtocol,
        **proxy,
    )
    return 0
