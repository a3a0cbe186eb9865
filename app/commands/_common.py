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


def setup_logging(verbose: bool = False) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
    )
