"""benchmarks/highres.py: kin shapes at full resolution, and posed characters sharing a template."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.core.cleaning import vertex_components
from app.core.mesh import load_mesh
from app.datasets.bodyplans import PLANS
from app.datasets.folder import read_labelled_folder
from benchmarks.highres import KIN, _rest_segments, fine_shape, generate, kin_chains, skin

pytestmark = pytest.mark.slow  # marching cubes of 20 bodies: ~40 s on 2 cores

SMALL = {"grid": 60, "vertex_range": (1_500, 2_000)}  # coarse and quick; the column uses grid 220


@pytest.fixture(scope="module")
def kin(tmp_path_factory) -> dict[str, object]:
    out = generate(tmp_path_factory.mktemp("kin"), "fine", per_class=1, seed=0, holes=(0, 0), **SMALL)
    return {r.label: load_mesh(r.path) for r in read_labelled_folder(out)}


def test_kin_shapes_are_labelled_fine_and_in_one_piece(kin):
    assert sorted(kin) == sorted(KIN)
    for mesh in kin.values():
        # decimated towards the range asked for (one quadric pass may stop short of it)
        assert 1_400 <= mesh.n_vertices <= 4_000
        # every small part is fused to its body: one connected surface
        assert len(np.unique(vertex_components(mesh))) == 1


def test_kin_shapes_are_reproducible():
    a = fine_shape("dog", np.random.default_rng([0, 1, 0, 30]), holes=(1, 1), **SMALL)
    b = fine_shape("dog", np.random.default_rng([0, 1, 0, 30]), holes=(1, 1), **SMALL)
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_array_equal(a.vertices, b.vertices)


def test_kin_classes_share_a_plan_and_differ_by_build_and_small_parts():
    base = PLANS["quadruped"]()
    dog, anchors = kin_chains("dog")
    assert [c.lengths for c in dog] == [c.lengths for c in base]  # the plan as it is
    camel, _ = kin_chains("camel")
    for leg in (1, 2, 3, 4):  # a camel's legs: 1.3 times as long, 0.9 times as thick
        np.testing.assert_allclose(camel[leg].lengths, np.array(base[leg].lengths) * 1.3)
        np.testing.assert_allclose(camel[leg].radii, np.array(base[leg].radii) * 0.9)
    assert camel[5].lengths[1] == base[5].lengths[1]  # the head, which carries the parts, keeps its size
    # parts are placed from the plan's own rest pose, whatever the class's proportions
    np.testing.assert_allclose(anchors[0], base[0].anchor)
    assert len(KIN["wolf"][1]) == 4  # two ears, a snout, a tuft


@pytest.mark.parametrize(("kind", "classes"), [("characters", 5), ("kin-characters", len(KIN))])
def test_characters_of_a_class_share_the_template_and_are_posed_isometrically(tmp_path: Path, kind, classes):
    out = generate(tmp_path / "d", kind, per_class=2, seed=0, **SMALL)
    by_class: dict[str, list] = {}
    for r in read_labelled_folder(out):
        by_class.setdefault(r.label, []).append(load_mesh(r.path))
    assert len(by_class) == classes
    for first, second in by_class.values():
        np.testing.assert_array_equal(first.faces, second.faces)  # one template, other poses
        assert not np.allclose(first.vertices, second.vertices)
        # relative to the total area, faces keep their area up to the skinning's creases (linear blend
        # skinning is not isometric: a median change of 5-10 %)
        ra = first.face_areas() / first.face_areas().sum()
        rb = second.face_areas() / second.face_areas().sum()
        assert np.median(np.abs(ra - rb) / ra) < 0.1


def test_skinning_with_the_rest_frames_is_the_identity():
    rest = _rest_segments(PLANS["hand"]())
    frames = [(np.asarray(a, dtype=float), np.eye(3)) for a, _, _, _ in rest]
    points = np.random.default_rng(0).normal(size=(50, 3))
    np.testing.assert_allclose(skin(points, rest, frames, rest), points, atol=1e-12)
