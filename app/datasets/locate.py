"""Where the evaluation datasets live: one setting, SHAPEBAG_DATASETS, for the tests, benchmarks and targets.

The datasets are never part of the repository. SHAPEBAG_DATASETS names a folder holding one sub-folder per
dataset (`shrec11-simplified/`, `realworld/`); unset, it is `../shared/datasets` beside the repository when
that folder exists. Whatever needs a dataset asks `require(name)`, which raises DatasetMissing with a
message naming the dataset, where it was looked for and how to get it (tests skip on it, commands stop).
"""

from __future__ import annotations

import os
from pathlib import Path

ENV = "SHAPEBAG_DATASETS"
# app/datasets/locate.py -> the repository root (a source checkout; an installed wheel has no ../shared)
REPO_ROOT = Path(__file__).resolve().parents[2]

# name -> (the file that proves the copy is complete, what it is; data/README.md says how to get it)
KNOWN: dict[str, tuple[str, str]] = {
    "shrec11-simplified": ("labels.csv", "SHREC'11 non-rigid as simplified by MeshCNN, with labels.csv"),
    "realworld": ("SOURCES.csv", "third-party mesh files with SOURCES.csv"),
}


class DatasetMissing(FileNotFoundError):
    """A dataset that a test, benchmark or target needs is not where SHAPEBAG_DATASETS points."""


def datasets_root() -> Path:
    """The folder of datasets: $SHAPEBAG_DATASETS, else ../shared/datasets beside the repository."""
    env = os.environ.get(ENV, "").strip()
    return Path(env).expanduser() if env else REPO_ROOT.parent / "shared" / "datasets"


def dataset_dir(name: str) -> Path:
    """Where dataset `name` is looked for (it may be absent: `require` checks)."""
    return datasets_root() / name


def missing_reason(name: str) -> str | None:
    """None when dataset `name` is present, else a sentence naming it and how to get it."""
    marker, how = KNOWN.get(name, ("", "a folder named after the dataset"))
    path = dataset_dir(name)
    if path.is_dir() and (not marker or (path / marker).is_file()):
        return None
    return f"dataset {name} ({how}) not found at {path}: set {ENV} to its parent folder (data/README.md)"


def require(name: str) -> Path:
    """The folder of dataset `name`; DatasetMissing (with how to get it) when it is absent."""
    reason = missing_reason(name)
    if reason is not None:
        raise DatasetMissing(reason)
    return dataset_dir(name)


def main(argv: list[str] | None = None) -> int:
    """`python -m app.datasets.locate NAME...`: print each dataset's folder, or why not and exit 2."""
    import sys

    names = (argv if argv is not None else sys.argv[1:]) or list(KNOWN)
    status = 0
    for name in names:
        reason = missing_reason(name)
        if reason is None:
            print(dataset_dir(name))
        else:
            print(reason, file=sys.stderr)
            status = 2
    return status


if __name__ == "__main__":
    raise SystemExit(main())
