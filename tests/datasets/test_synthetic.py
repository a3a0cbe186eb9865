"""The synthetic corpus: deterministic, labelled, closed meshes the core can load."""

from __future__ import annotations

import hashlib
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import trimesh

from app.core.mesh import load_mesh
from app.datasets.bodyplans import PLANS
from app.datasets.folder import read_labelled_folder
from app.datasets.synthetic import MAX_VERTICES, generate, make_shape, refine


def _digest(root: Path) -> dict[str, str]:
    files = sorted(p for p in root.rglob("*") if p.is_file())
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in files}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate(tmp_path_factory.mktemp("synthetic"), classes=3, per_class=2, seed=7)


def test_labels_and_counts(corpus: Path) -> None:
    rows = read_labelled_folder(corpus)
    assert Counter(r.label for r in rows) == {"quadruped": 2, "biped": 2, "bird": 2}
    assert (corpus / "labels.csv").read_text().splitlines()[0] == "file,class"
    assert not list(corpus.rglob(".*"))  # no temporary files left behind


def test_same_seed_same_bytes_other_seed_other_shapes(corpus: Path, tmp_path: Path) -> None:
    assert _digest(generate(tmp_path / "again", classes=3, per_class=2, seed=7)) == _digest(corpus)
    other = _digest(generate(tmp_path / "other", classes=3, per_class=2, seed=8))
    assert other.keys() == _digest(corpus).keys()
    assert other["quadruped/quadruped_00.obj"] != _digest(corpus)["quadruped/quadruped_00.obj"]


def test_meshes_are_closed_single_pieces_the_core_can_load(corpus: Path) -> None:
    for row in read_labelled_folder(corpus):
        raw = trimesh.load(row.path, process=False)
        assert raw.is_watertight, row.path
        assert len(raw.split(only_watertight=False)) == 1, row.path
        assert raw.volume > 0  # outward normals
        mesh = load_mesh(row.path)
        assert 500 <= mesh.n_vertices <= MAX_VERTICES + 5


def test_instances_differ_in_pose_scale_and_position() -> None:
    a, _ = make_shape("biped", np.random.default_rng([0, 1, 0]))
    b, _ = make_shape("biped", np.random.default_rng([0, 1, 1]))
    assert np.abs(a.mean(axis=0) - b.mean(axis=0)).max() > 0.01  # random translation
    assert abs(np.ptp(a, axis=0).max() / np.ptp(b, axis=0).max() - 1) > 0.01  # random scale (and pose)


@pytest.mark.parametrize("plan", sorted(PLANS))
def test_every_body_plan_is_one_closed_surface(plan: str) -> None:
    vertices, faces = make_shape(plan, np.random.default_rng(123))
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight
    assert len(mesh.split(only_watertight=False)) == 1


@pytest.mark.parametrize(("classes", "per_class"), [(0, 2), (len(PLANS) + 1, 2), (2, 0)])
def test_bad_arguments(tmp_path: Path, classes: int, per_class: int) -> None:
    with pytest.raises(ValueError):
        generate(tmp_path, classes=classes, per_class=per_class)
    assert not (tmp_path / "labels.csv").exists()


def test_refine_keeps_each_surface_and_its_label_at_a_finer_resolution(corpus: Path, tmp_path: Path) -> None:
    fine = refine(corpus, tmp_path / "fine", min_vertices=12_000)
    assert [(r.path.relative_to(fine), r.label) for r in read_labelled_folder(fine)] == [
        (r.path.relative_to(corpus), r.label) for r in read_labelled_folder(corpus)]
    for row in read_labelled_folder(corpus):
        before = trimesh.load(row.path, force="mesh", process=False)
        after = trimesh.load(fine / row.path.relative_to(corpus), force="mesh", process=False)
        assert len(before.vertices) < 12_000 <= len(after.vertices) < 4 * 12_000
        # every new vertex is an edge midpoint: the same surface, so the same area and volume
        assert after.area == pytest.approx(before.area, rel=1e-6)
        assert after.volume == pytest.approx(before.volume, rel=1e-6)
        np.testing.assert_allclose(after.bounds, before.bounds, atol=1e-6)
    assert _digest(refine(corpus, tmp_path / "again", min_vertices=12_000)) == _digest(fine)  # deterministic
