"""benchmarks/rigid.py: rigid, man-made classes as a solid modeller triangulates them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.core.holes import boundary_loops
from app.core.mesh import Mesh, load_mesh
from app.datasets.folder import read_labelled_folder
from benchmarks import rigid  # manifold3d, from the dev extra

# genus of each class's solid: a handle, a bore, one or two holes per flange of the bracket
GENUS = {"mug": {1}, "gear": {1}, "bracket": {2, 4}}


def test_every_class_is_one_closed_solid_of_its_genus_and_reproducible(tmp_path: Path):
    a = rigid.generate(tmp_path / "a", per_class=3, seed=0)
    b = rigid.generate(tmp_path / "b", per_class=3, seed=0)
    rows = read_labelled_folder(a)
    assert sorted({r.label for r in rows}) == sorted(rigid.CLASSES) and len(rows) == 3 * len(rigid.CLASSES)
    for row in rows:
        mesh = load_mesh(row.path)
        assert boundary_loops(mesh.faces, mesh.n_vertices) == [], row.path  # watertight: no hole anywhere
        euler = _euler(mesh)
        assert euler % 2 == 0 and euler <= 2, (row.path, euler)  # one piece (χ = 2 - 2g; two pieces: 4)
        assert (1 - euler // 2) in GENUS.get(row.label, {0}), (row.path, euler)
        assert (b / row.path.relative_to(a)).read_bytes() == row.path.read_bytes()


def _euler(mesh: Mesh) -> int:
    """V - E + F."""
    edges = np.unique(np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    return mesh.n_vertices - len(edges) + len(mesh.faces)


def test_instances_differ_in_proportions_and_tessellation(tmp_path: Path):
    out = rigid.generate(tmp_path / "c", classes=1, per_class=4, seed=0)  # mugs
    meshes = [load_mesh(r.path) for r in read_labelled_folder(out)]
    assert len({m.n_vertices for m in meshes}) > 1  # the chord tolerance is drawn per instance
    # scale-free proportion: area^(3/2) / volume differs between instances (not only the size)
    ratios = []
    for m in meshes:
        t = m.vertices[m.faces]
        volume = abs(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum()) / 6
        ratios.append(m.face_areas().sum() ** 1.5 / volume)
    assert np.ptp(ratios) / np.mean(ratios) > 0.02
