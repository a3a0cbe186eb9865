"""`shapebag` command line: each subcommand lives in app/commands/<name>.py with
`register(subparsers)` adding its parser and setting `func(args) -> int`."""

from __future__ import annotations

import argparse
import importlib
import sys

# order = order in --help
COMMANDS = ("serve", "worker", "ingest", "search", "variants", "vocabulary", "evaluate", "demo")


class CommandError(Exception):
    """A user-facing failure: printed as one line, exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="shapebag", description="non-rigid 3D shape retrieval (HKS + BoF)")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMANDS:
        importlib.import_module(f"app.commands.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except CommandError as exc:
        print(f"shapebag {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # `python -m app.cli`: run the imported module's main, so that the commands'
    from app.cli import main as _main  # CommandError (app.cli's) is the class caught, not __main__'s

    sys.exit(_main())
