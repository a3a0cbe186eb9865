"""labels.csv reader: good folders read in order; every kind of broken folder named clearly."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.datasets import locate
from app.datasets.folder import DatasetError, LabelledFile, read_labelled_folder
from tests.conftest import needs_dataset

SHREC = locate.dataset_dir("shrec11-simplified")


def _folder(tmp_path: Path, csv_text: str, files: list[str]) -> Path:
    for name in files:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("v 0 0 0\n")
    (tmp_path / "labels.csv").write_text(csv_text)
    return tmp_path


def test_reads_rows_in_order_with_optional_split(tmp_path: Path) -> None:
    root = _folder(tmp_path, "file,class,split\na/x.obj,cat,train\nb.obj,dog,test\n", ["a/x.obj", "b.obj"])
    rows = read_labelled_folder(root)
    assert rows == [
        LabelledFile(path=(root / "a/x.obj").resolve(), label="cat", split="train"),
        LabelledFile(path=(root / "b.obj").resolve(), label="dog", split="test"),
    ]


def test_two_columns_header_case_spaces_and_bom(tmp_path: Path) -> None:
    root = _folder(tmp_path, "\ufeffFile , Class\n x.obj , horse \n", ["x.obj"])
    (row,) = read_labelled_folder(str(root))
    assert row.label == "horse" and row.split is None and row.path.name == "x.obj"


def test_missing_labels_csv(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no labels.csv"):
        read_labelled_folder(tmp_path)


def test_not_a_directory(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="not a directory"):
        read_labelled_folder(tmp_path / "nope")


@pytest.mark.parametrize("header", ["name,class", "file,label", "", "file"])
def test_bad_header(tmp_path: Path, header: str) -> None:
    root = _folder(tmp_path, header + "\nx.obj,cat\n", ["x.obj"])
    with pytest.raises(DatasetError, match="header"):
        read_labelled_folder(root)


def test_missing_files_are_all_counted(tmp_path: Path) -> None:
    rows = "".join(f"m{i}.obj,cat\n" for i in range(8))
    root = _folder(tmp_path, "file,class\n" + rows, ["m0.obj"])
    with pytest.raises(DatasetError, match=r"7 file\(s\) that do not exist: m1.obj.*and 2 more"):
        read_labelled_folder(root)


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        ("x.obj,\n", "must be filled"),
        ("../x.obj,cat\n", "outside"),
        ("x.obj,cat\nx.obj,dog\n", "listed twice"),
        ("", "no meshes"),
    ],
)
def test_bad_rows(tmp_path: Path, rows: str, message: str) -> None:
    root = _folder(tmp_path / "d", "file,class\n" + rows, ["x.obj"])
    (tmp_path / "x.obj").write_text("v 0 0 0\n")
    with pytest.raises(DatasetError, match=message):
        read_labelled_folder(root)


def test_dataset_error_is_a_value_error() -> None:
    assert issubclass(DatasetError, ValueError)


@needs_dataset("shrec11-simplified")
def test_reads_the_shrec_folder() -> None:
    rows = read_labelled_folder(SHREC)
    assert len(rows) == 600
    assert len({r.label for r in rows}) == 30
    assert {r.split for r in rows} <= {"train", "test"}
