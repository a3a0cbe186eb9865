"""A folder of meshes, labelled by `labels.csv` (header `file,class[,split]`) next to the mesh files.

`file` is a path relative to the folder (sub-folders allowed, never outside it); `class` is the label.
Everything is checked before anything is returned, so a bulk ingest never starts on a broken folder.
An evaluation needs every label (read_labelled_folder); an ingestion takes any folder of meshes, with
or without labels (read_mesh_folder).
"""

from __future__ import annotations

import csv
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path

from app.core.formats import SUPPORTED_FORMATS

LABELS_FILE = "labels.csv"
REQUIRED_COLUMNS = ("file", "class")


class DatasetError(ValueError):
    """The folder cannot be read as a labelled dataset; the message says what to fix."""


@dataclass(frozen=True)
class LabelledFile:
    path: Path  # absolute path of the mesh file
    label: str
    split: str | None = None  # the optional third column ("train" / "test"), when present


@dataclass(frozen=True)
class MeshFile:
    path: Path  # absolute path of the mesh file
    label: str | None  # None: unlabelled (no labels.csv, or an empty class cell)
    split: str | None = None


def read_labelled_folder(directory: Path | str) -> list[LabelledFile]:
    """Read `directory/labels.csv` -> one LabelledFile per row, in file order.

    Raises DatasetError for: a missing directory or labels.csv, a header without `file` and `class`,
    an empty label or file cell, a path leaving the folder, a duplicated file, a listed file that does
    not exist (all missing files are named, up to a few), or a file with no rows.
    """
    root = _directory(directory)
    labels = root / LABELS_FILE
    if not labels.is_file():
        raise DatasetError(
            f"{root} has no {LABELS_FILE} (expected a header `file,class` and one row per mesh)"
        )
    rows = _read_rows(root, labels, REQUIRED_COLUMNS)
    return [LabelledFile(path, label, split) for path, label, split in rows if label is not None]


def read_mesh_folder(directory: Path | str, formats: Collection[str] = SUPPORTED_FORMATS) -> list[MeshFile]:
    """The meshes of `directory` to ingest, labelled where a label is known.

    With a labels.csv: its rows, in file order, checked as read_labelled_folder checks them, except
    that the `class` column and its cells may be missing or empty (those meshes are unlabelled). Without
    one: every file under the folder whose extension is a readable format (`formats`), in path order,
    unlabelled; hidden files and folders (".name") are skipped. Raises DatasetError when there is
    nothing to ingest.
    """
    root = _directory(directory)
    labels = root / LABELS_FILE
    if labels.is_file():
        return [MeshFile(path, label, split) for path, label, split in _read_rows(root, labels, ("file",))]
    base = root.resolve()
    found = sorted(
        path for path in base.rglob("*")
        if path.suffix.lower().lstrip(".") in formats and path.is_file()
        and not any(part.startswith(".") for part in path.relative_to(base).parts)
        and path.resolve().is_relative_to(base)  # a link leading out of the folder is not its mesh
    )
    if not found:
        raise DatasetError(
            f"{root} holds no mesh files ({', '.join('.' + f for f in formats)}) and no {LABELS_FILE}"
        )
    return [MeshFile(path, None) for path in found]


def _directory(directory: Path | str) -> Path:
    root = Path(directory)
    if not root.is_dir():
        raise DatasetError(f"{root} is not a directory")
    return root


def _read_rows(
    root: Path, labels: Path, required: tuple[str, ...]
) -> list[tuple[Path, str | None, str | None]]:
    """(absolute path, label or None, split or None) per row of `labels`; `required` columns must be
    in the header and their cells filled in."""
    try:
        text = labels.read_text(encoding="utf-8-sig")  # tolerate a BOM written by spreadsheet programs
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read {labels}: {exc}") from exc

    reader = csv.DictReader(text.splitlines())
    header = [name.strip().lower() for name in (reader.fieldnames or [])]
    missing = [c for c in required if c not in header]
    if missing:
        raise DatasetError(
            f"{labels} header must name the columns file,class[,split]; missing: {', '.join(missing)}"
        )
    reader.fieldnames = header
    base = root.resolve()
    out: list[tuple[Path, str | None, str | None]] = []
    seen: set[Path] = set()
    absent: list[str] = []
    for line, row in enumerate(reader, start=2):
        name = (row.get("file") or "").strip()
        label = (row.get("class") or "").strip()
        if not name or (not label and "class" in required):
            raise DatasetError(f"{labels}:{line}: both `file` and `class` must be filled in"
                               if "class" in required else f"{labels}:{line}: `file` must be filled in")
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
        out.append((path, label or None, split))
    if absent:
        shown = ", ".join(absent[:5]) + (f" and {len(absent) - 5} more" if len(absent) > 5 else "")
        raise DatasetError(f"{labels} lists {len(absent)} file(s) that do not exist: {shown}")
    if not out:
        raise DatasetError(f"{labels} lists no meshes")
    return out
