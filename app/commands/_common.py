"""Helpers shared by the CLI commands (settings from flags + SHAPEBAG_* env)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path


def add_data_dir(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--data-dir", type=Path, default=None, help="data directory (default: $SHAPEBAG_DATA_DIR or var/data)"
    )


def settings_from(args: argparse.Namespace, **overrides):  # -> Settings (imported lazily: keeps --help fast)
    from app.config import Settings

    values = {k: v for k, v in overrides.items() if v is not None}
    if getattr(args, "data_dir", None) is not None:
        values["data_dir"] = args.data_dir
    return Settings(**values)


def setup_logging(verbose: bool = False) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
    )
