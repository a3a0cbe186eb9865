"""benchmarks/variants.py: another triangulation of the same surfaces, labels kept."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from app.core.mesh import load_mesh
from app.datasets.folder import read_labelled_folder
from benchmarks.variants import generate
from tests.conftest import dataset_or_skip


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    shrec = dataset_or_skip("shrec11-simplified")
    root = tmp_path_factory.mktemp("src")
    lines = ["file,class,split"]
    for cls in ("alien", "hand"):
        (root / cls).mkdir()
        for src in sorted((shrec / cls / "train").glob("*.obj"))[:2]:
            shutil.copy(src, root / cls / src.name)
            lines.append(f"{cls}/{src.name},{cls},train")
    (root / "labels.csv").write_text("\n".join(lines) + "\n")
    return root


def _bbox(vertices: np.ndarray) -> np.ndarray:
    return np.ptp(vertices, axis=0)


def test_remesh_keeps_labels_and_surface_and_changes_the_triangulation(source: Path, tmp_path: Path):
    out = generate(source, tmp_path / "remesh", kind="remesh", seed=0)
    src_rows, out_rows = read_labelled_folder(source), read_labelled_folder(out)
    assert [r.label for r in out_rows] == [r.label for r in src_rows]
    assert [r.path.relative_to(out) for r in out_rows] == [r.path.relative_to(source) for r in src_rows]
    counts = []
    for a, b in zip(src_rows, out_rows, strict=True):
        mesh, variant = load_mesh(a.path), load_mesh(b.path)
        counts.append(variant.n_vertices)
        # a new triangulation: 1k-8k vertices instead of ~250, hardly any vertex where one was
        assert 900 <= variant.n_vertices <= 8000 and variant.n_vertices > 3 * mesh.n_vertices
        # of the same surface: area and bounding box within 2 %
        area, new_area = mesh.face_areas().sum(), variant.face_areas().sum()
        assert new_area == pytest.approx(area, rel=0.02)
        assert np.allclose(_bbox(variant.vertices), _bbox(mesh.vertices), rtol=0.02)
    assert len(set(counts)) == len(counts)  # each mesh its own random resolution
    # the same arguments give the same files
    again = generate(source, tmp_path / "again", kind="remesh", seed=0)
    first = out_rows[0].path.relative_to(out)
    assert (again / first).read_bytes() == (out / first).read_bytes()


def test_noise_keeps_the_connectivity_and_moves_the_vertices(source: Path, tmp_path: Path):
    out = generate(source, tmp_path / "noise", kind="noise", nsr=0.01)
    for a, b in zip(read_labelled_folder(source), read_labelled_folder(out), strict=True):
        mesh, noisy = load_mesh(a.path), load_mesh(b.path)
        assert np.array_equal(mesh.faces, noisy.faces)
        ratio = (noisy.vertices - mesh.vertices).var(axis=0) / mesh.vertices.var(axis=0)
        assert np.all((ratio > 0.005) & (ratio < 0.02))  # NSR 0.01 per axis, from ~250 samples


def test_unknown_kind_is_refused(source: Path, tmp_path: Path):
    with pytest.raises(ValueError, match="kind"):
        generate(source, tmp_path / "x", kind="blur")
