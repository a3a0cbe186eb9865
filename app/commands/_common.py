"""Helpers shared by the CLI commands (settings from flags + SHAPEBAG_* env).

The data directory is resolved explicitly, in this order, and every command says which one it uses:
`--data-dir` > `$SHAPEBAG_DATA_DIR` > `data` under the current directory (DEFAULT_DATA_DIR: in a checkout,
its data/). A command that only reads (`search`, `vocabulary show`) refuses a directory holding no database
instead of creating an empty one there: run from another folder, it would otherwise answer "no vocabulary
is active yet".
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path

from app.cli import CommandError

DEFAULT_DATA_DIR = Path("data")
DATABASE_FILE = "shapebag.db"  # app.services.context opens <data dir>/shapebag.db


def add_data_dir(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--data-dir",
        type=Path,
        default=None,
        help=f"data directory (default: $SHAPEBAG_DATA_DIR, else {DEFAULT_DATA_DIR} under the current one)",
    )


def resolve_data_dir(
    flag: Path | None, default: Path = DEFAULT_DATA_DIR, use_env: bool = True
) -> tuple[Path, str]:
    """(absolute data directory, where it came from): the flag, then the environment, then `default`."""
    if flag is not None:
        return flag.expanduser().resolve(), "--data-dir"
    env = os.environ.get("SHAPEBAG_DATA_DIR") if use_env else None
    if env:
        return Path(env).expanduser().resolve(), "SHAPEBAG_DATA_DIR"
    return default.resolve(), f"default {default}"


def settings_from(
    args: argparse.Namespace,
    *,
    must_exist: bool = False,
    default_data_dir: Path = DEFAULT_DATA_DIR,
    use_env: bool = True,
    **overrides,
):  # -> Settings (imported lazily: keeps --help fast)
    """Settings from the flags and the environment, the data directory resolved and printed (stderr).

    must_exist: refuse (CommandError) a data directory without a database, naming it and how to fix it.
    use_env=False: ignore $SHAPEBAG_DATA_DIR (the demo never writes into the user's own data)."""
    from app.config import Settings

    values = {k: v for k, v in overrides.items() if v is not None}
    if hasattr(args, "data_dir"):
        data_dir, source = resolve_data_dir(args.data_dir, default_data_dir, use_env)
        on_server = bool(os.environ.get("SHAPEBAG_DATABASE_URL"))  # PostgreSQL: the data dir is only a cache
        if must_exist and not on_server and not (data_dir / DATABASE_FILE).is_file():
            raise CommandError(
                f"no shapebag data in {data_dir} ({source}): pass --data-dir or set SHAPEBAG_DATA_DIR to the "
                f"directory the server or `shapebag ingest` uses"
            )
        print(f"data directory: {data_dir} ({source})", file=sys.stderr)
        values["data_dir"] = data_dir
    return Settings(**values)


class OncePerInterval(logging.Filter):
    """Lets one record of a repeating message through per `interval_s`, without its traceback, with
    how many were held back: asyncio logs every refused accept() (no descriptor left) with a
    traceback, 741,375 of them (330 MB) in 40 s of a connection flood (red team, 2026-12-05)."""

    def __init__(self, prefix: str, interval_s: float = 10.0) -> None:
        super().__init__()
        self.prefix, self.interval_s = prefix, interval_s
        self.last, self.held = float("-inf"), 0

    def filter(self, record: logging.LogRecord) -> bool:
        if not str(record.msg).startswith(self.prefix):
            return True
        if record.created - self.last < self.interval_s:
            self.held += 1
            return False
        if self.held:
            record.msg = f"{record.msg} ({self.held} more in the last {self.interval_s:g} s, not logged)"
        record.exc_info, record.exc_text, record.stack_info = None, None, None
        self.last, self.held = record.created, 0
        return True


def setup_logging(verbose: bool = False) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
    )
    quiet = logging.getLogger("asyncio")
    if not any(isinstance(f, OncePerInterval) for f in quiet.filters):
        quiet.addFilter(OncePerInterval("socket.accept() out of system resource"))
