"""`shapebag demo`: generate the synthetic corpus (if absent), ingest it, serve it. `make run` runs this."""

from __future__ import annotations

import argparse
import os

from app.commands._common import add_data_dir, settings_from


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("demo", help="generate + ingest a synthetic labelled corpus, then serve it")
    add_data_dir(p)
    p.add_argument("--host", default=None, help="bind address (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=None, help="port (default 8000)")
    p.add_argument("--classes", type=int, default=6, help="body plans (default 6)")
    p.add_argument("--per-class", type=int, default=8, help="shapes per body plan (default 8)")
    p.add_argument("--no-serve", action="store_true", help="stop after ingesting")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from app.commands.ingest import ingest_folder
    from app.commands.serve import serve
    from app.datasets.synthetic import generate

    # the demo is a local playground: dev mode unless the environment says otherwise
    dev = None if os.environ.get("SHAPEBAG_ADMIN_TOKEN") else True
    settings = settings_from(args, host=args.host, port=args.port, dev_mode=dev)
    corpus = settings.data_dir / "corpus"
    if not (corpus / "labels.csv").is_file():
        print(f"generating {args.classes} x {args.per_class} synthetic shapes into {corpus} ...")
        generate(corpus, classes=args.classes, per_class=args.per_class, seed=0)
    ingest_folder(settings, corpus, os.cpu_count() or 1)
    if args.no_serve:
        return 0
    return serve(settings)
