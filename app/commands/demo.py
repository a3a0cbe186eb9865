"""`shapebag demo`: generate the synthetic corpus (if absent), ingest it, serve it. `make run` runs this.

The demo lives in its own data directory (`make run`: var/demo), never in the one holding your models
(`make serve`: var/data): its synthetic "hand" or "biped" shapes would otherwise answer real queries."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from app.commands._common import settings_from

DEMO_DATA_DIR = Path("var/demo")  # apart from var/data (the user's): `make clean-demo` removes it


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("demo", help="generate + ingest a synthetic labelled corpus, then serve it")
    p.add_argument(
        "--data-dir", type=Path, default=None,
        help=f"where the demo lives (default {DEMO_DATA_DIR}; never $SHAPEBAG_DATA_DIR, your own data)",
    )
    p.add_argument("--host", default=None, help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="port (default 8000)")
    p.add_argument("--classes", type=int, default=6, help="body plans (default 6)")
    p.add_argument("--per-class", type=int, default=8, help="shapes per body plan (default 8)")
    p.add_argument("--no-serve", action="store_true", help="stop after ingesting")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from app.commands.ingest import ingest_folder
    from app.commands.serve import check_port_free, serve
    from app.datasets.synthetic import generate

    # the demo is a local playground: dev mode unless the environment says otherwise
    dev = None if os.environ.get("SHAPEBAG_ADMIN_TOKEN") else True
    settings = settings_from(
        args, default_data_dir=DEMO_DATA_DIR, use_env=False, host=args.host, port=args.port, dev_mode=dev
    )
    if not args.no_serve:  # before generating and ingesting, not after
        check_port_free(settings.host, settings.port)
    corpus = settings.data_dir / "corpus"
    print(f"the demo's own data directory: {settings.data_dir} (start clean: delete it, or make clean-demo)")
    if not (corpus / "labels.csv").is_file():
        print(f"generating {args.classes} x {args.per_class} synthetic shapes into {corpus} ...")
        generate(corpus, classes=args.classes, per_class=args.per_class, seed=0)
    ingest_folder(settings, corpus, os.cpu_count() or 1)
    if args.no_serve:
        return 0
    return serve(settings)
