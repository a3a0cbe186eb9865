"""benchmarks.partial_objects: plates built as the variant benchmark builds them, split into their
objects, and the least distance over a model's rows; figures by hand."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import trimesh

from app.core.mesh import load_mesh
from app.core.variants.surface import objects
from app.datasets.folder import read_labelled_folder
from benchmarks import partial_objects as po


def test_a_models_distance_is_the_least_over_its_rows():
    whole = np.array([[0.0, 0.0], [4.0, 0.0], [9.0, 9.0]])
    parts = np.array([[1.0, 0.0], [0.0, 0.5]])  # two objects of model 2
    owner = np.array([2, 2])
    d = po.least_over_rows(np.array([0.0, 0.0]), whole, parts, owner)
    assert d.tolist() == [0.0, 4.0, 0.5]
    assert po.least_over_rows(np.zeros(2), whole, parts[:0], owner[:0]).tolist() == [0.0, 4.0, 18.0]


def test_whole_query_scores_by_hand_with_a_plate_that_holds_a_class():
    """Labels a, a, b, b on a line at 0, 10, 1, 11, and a plate (model 4) holding an `a`, its whole row
    far off at 50. Whole rows: APs 1/2, 5/12, 1/3, 1/2 (the plate last, relevant to the a's only).
    An object row at 0.2 brings the plate first for queries 0 (relevant) and 2 (not): APs 5/6, 5/12,
    1/4, 1/2."""
    whole = np.array([[0.0], [10.0], [1.0], [11.0], [50.0]])
    labels = np.array(["a", "a", "b", "b"])
    holds = [("a",)]
    before = po.whole_query_scores(whole, whole[:0], np.zeros(0, np.int64), labels, holds)
    assert before["mAP"] == pytest.approx((1 / 2 + 5 / 12 + 1 / 3 + 1 / 2) / 4)
    assert before["NN"] == 0.0 and before["plate first"] == 0.0
    after = po.whole_query_scores(whole, np.array([[0.2]]), np.array([4]), labels, holds)
    assert after["mAP"] == pytest.approx((5 / 6 + 5 / 12 + 1 / 4 + 1 / 2) / 4)
    assert after["NN"] == 0.25 and after["plate first"] == 0.5


@pytest.fixture()
def folder(tmp_path):
    meshes = {"ball.obj": ("round", trimesh.creation.icosphere(2)),
              "box.obj": ("square", trimesh.creation.box()),
              "tube.obj": ("long", trimesh.creation.cylinder(0.3, 2.0))}
    with open(tmp_path / "labels.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["file", "class"])
        for name, (label, mesh) in meshes.items():
            mesh.export(tmp_path / name)
            w.writerow([name, label])
    return tmp_path


def test_plates_hold_their_base_and_split_into_as_many_objects(folder, tmp_path):
    rows = read_labelled_folder(folder)
    chosen = po.bases(rows, 1)
    assert chosen == [1, 2]  # index 0 is in the picking split
    plates = po.build_plates(rows, chosen, tmp_path / "plates")
    assert [(p.kind, p.base) for p in plates] == [("copies", 1), ("member", 1), ("copies", 2), ("member", 2)]
    assert all(2 <= p.objects <= 6 for p in plates)
    assert all(p.classes == (p.label,) for p in plates if p.kind == "copies")
    assert all(p.label in p.classes and len(p.classes) > 1 for p in plates if p.kind == "member")
    plate_rows = po._mesh_rows(tmp_path / "plates", [p.file for p in plates])
    for p, row in zip(plates, plate_rows, strict=True):
        assert row.label == rows[p.base].label
        assert len(objects(load_mesh(row.path))) == p.objects  # apart on the grid: one object each
    owner, names = po.split_objects(plate_rows, tmp_path / "objects", max_objects=3)
    assert owner == sorted(owner) and len(owner) == sum(min(p.objects, 3) for p in plates)
    assert [r.path.name for r in po._mesh_rows(tmp_path / "objects", names)] == names
    assert names[0] == f"{plate_rows[owner[0]].path.stem}__o0.obj"
