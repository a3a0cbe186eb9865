"""`shapebag serve`: the REST API (and its embedded workers) with uvicorn."""

from __future__ import annotations

import argparse

from app.cli import CommandError
from app.commands._common import add_data_dir, settings_from, setup_logging


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("serve", help="serve the REST API and the web page")
    add_data_dir(p)
    p.add_argument("--host", default=None, help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="port (default 8000)")
    p.add_argument("--workers", type=int, default=None, help="embedded ingestion processes (default: cores)")
    p.add_argument("--dev", action="store_true", help="dev mode: allows the default admin token")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        settings = settings_from(
            args, host=args.host, port=args.port, workers=args.workers, dev_mode=True if args.dev else None
        )
    except ValueError as exc:
        raise CommandError(str(exc)) from exc
    return serve(settings)


def serve(settings) -> int:
    import uvicorn

    from app.config import DEFAULT_ADMIN_TOKEN
    from app.main import create_app

    setup_logging(verbose=True)
    try:
        app = create_app(settings)
    except ValueError as exc:  # e.g. the default admin token outside dev mode
        raise CommandError(str(exc)) from exc
    print(f"shapebag: serving {settings.data_dir} on http://{settings.host}:{settings.port}/ (docs at /docs)")
    if settings.dev_mode and settings.admin_token == DEFAULT_ADMIN_TOKEN:  # the README's admin calls need it
        token = DEFAULT_ADMIN_TOKEN
        print(f"shapebag: dev mode, admin token {token!r}: curl -H 'X-Admin-Token: {token}' ...")
    uvicorn.run(app, host=settings.host, port=settings.port, log_level="info")
    return 0
