"""A labelled folder of meshes: `labels.csv` (header `file,class[,split]`) next to the mesh files.

`file` is a path relative to the folder (sub-folders allowed, never outside it); `class` is the label.
Everything is checked before anything is returned, so a bulk ingest never starts on a broken folder.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

LABELS_FILE = "labels.csv"
REQUIRED_COLUMNS = ("file", "class")


class DatasetError(ValueError):
    """The folder cannot be read as a labelled dataset; the message says what to fix."""


@dataclass(frozen=True)
class LabelledFile:
    path: Path  # absolute path of the mesh file
    label: str
    split: str | None = None  # the optional third column ("train" / "test"), when present


def read_labelled_folder(directory: Path | str) -> list[LabelledFile]:
    """Read `directory/labels.csv` -> one LabelledFile per row, in file order.

    Raises DatasetError for: a missing directory or labels.csv, a header without `file` and `class`,
    an empty label or file cell, a path leaving the folder, a duplicated file, a listed file that does
    not exist (all missing files are named, up to a few), or a file with no rows.
    """
    root = Path(directory)
    if not root.is_dir():
        raise DatasetError(f"{root} is not a directory")
    labels = root / LABELS_FILE
    if not labels.is_file():
        raise DatasetError(
            f"{root} has no {LABELS_FILE} (expected a header `file,class` and one row per mesh)"
        )
    try:
        text = labels.read_text(encoding="utf-8-sig")  # tolerate a BOM written by spreadsheet programs
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read {labels}: {exc}") from exc

    reader = csv.DictReader(text.splitlines())
    header = [name.strip().lower() for name in (reader.fieldnames or [])]
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise DatasetError(
            f"{labels} header must name the columns file,class[,split]; missing: {', '.join(missing)}"
        )
    reader.fieldnames = header
    base = root.resolve()
    out: list[LabelledFile] = []
    seen: set[Path] = set()
    absent: list[str] = []
    for line, row in enumerate(reader, start=2):
        name = (row.get("file") or "").strip()
        label = (row.get("class") or "").strip()
        if not name or not label:
            raise DatasetError(f"{labels}:{line}: both `file` and `class` must be filled in")
        path = (base / name).resolve()
        if not path.is_relative_to(base):
            raise DatasetError(f"{labels}:{line}: {name!r} points outside {root}")
        if path in seen:
            raise DatasetError(f"{labels}:{line}: {name!r} is listed twice")
        seen.add(path)
        if not path.is_file():
            absent.append(name)
            continue
        split = (row.get("split") or "").strip() or None
        out.append(LabelledFile(path=path, label=label, split=split))
    if absent:
        shown = ", ".join(absent[:5]) + (f" and {len(absent) - 5} more" if len(absent) > 5 else "")
        raise DatasetError(f"{labels} lists {len(absent)} file(s) that do not exist: {shown}")
    if not out:
        raise DatasetError(f"{labels} lists no meshes")
    return out
