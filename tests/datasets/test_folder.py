"""labels.csv reader: good folders read in order; every kind of broken folder named clearly."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.datasets.folder import DatasetError, LabelledFile, MeshFile, read_labelled_folder, read_mesh_folder

SHREC = Path(__file__).resolve().parents[3] / "shared" / "datasets" / "shrec11-simplified"


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


def test_a_folder_without_labels_csv_gives_every_mesh_file_unlabelled(tmp_path: Path) -> None:
    root = tmp_path / "d"
    names = ("b/chair.OBJ", "a.ply", "b/c/lamp.glb", "notes.txt", ".hidden/x.obj", "b/.x.stl", "scan.xyz")
    for name in names:
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text("v 0 0 0\n")
    items = read_mesh_folder(root)
    found = [i.path.relative_to(root.resolve()).as_posix() for i in items]
    assert found == ["a.ply", "b/c/lamp.glb", "b/chair.OBJ"]  # path order; not text, hidden or point clouds
    assert all(isinstance(i, MeshFile) and i.label is None and i.path.is_absolute() for i in items)
    with pytest.raises(DatasetError, match="labels.csv"):
        read_labelled_folder(root)  # an evaluation still needs every label


def test_empty_classes_and_a_file_only_header_are_unlabelled_for_ingestion(tmp_path: Path) -> None:
    root = _folder(tmp_path / "d", "file,class\nx.obj,\ny.obj,cup\n", ["x.obj", "y.obj", "z.obj"])
    assert [(i.path.name, i.label) for i in read_mesh_folder(root)] == [("x.obj", None), ("y.obj", "cup")]
    with pytest.raises(DatasetError, match="both `file` and `class` must be filled in"):
        read_labelled_folder(root)
    only_files = _folder(tmp_path / "e", "file\nz.obj\n", ["z.obj"])
    assert read_mesh_folder(only_files) == [MeshFile((only_files / "z.obj").resolve(), None)]
    broken = _folder(tmp_path / "f", "file,class\n,cup\n", ["w.obj"])
    with pytest.raises(DatasetError, match="`file` must be filled in"):
        read_mesh_folder(broken)


def test_a_folder_with_no_mesh_is_refused_naming_the_formats(tmp_path: Path) -> None:
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "readme.txt").write_text("hi")
    with pytest.raises(DatasetError, match=r"no mesh files \(\.obj, \.off, .*\) and no labels.csv"):
        read_mesh_folder(tmp_path / "d")


def test_dataset_error_is_a_value_error() -> None:
    assert issubclass(DatasetError, ValueError)


@pytest.mark.skipif(not (SHREC / "labels.csv").is_file(), reason="SHREC'11 simplified not present")
def test_reads_the_shrec_folder() -> None:
    rows = read_labelled_folder(SHREC)
    assert len(rows) == 600
    assert len({r.label for r in rows}) == 30
    assert {r.split for r in rows} <= {"train", "test"}
