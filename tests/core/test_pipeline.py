"""describe(): the whole per-shape computation, its invariances and its persistence."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from app.core.mesh import Mesh, clean
from app.core.pipeline import DescribeParams, ShapeDescription, describe
from app.core.vocabulary import Vocabulary, l1_distance


@pytest.fixture(scope="module")
def base_and_vocabulary(shrec_mesh):
    base = describe(shrec_mesh)
    # a vocabulary fit on this shape's own vertices: every word is in use, so any change shows in the BoF
    vocab = Vocabulary.fit([base], size=16, keypoints_only=False)
    return base, vocab


def _transformed(mesh: Mesh, rotation: np.ndarray, kind: str) -> Mesh:
    if kind == "rotation":
        return Mesh(mesh.vertices @ rotation.T, mesh.faces)
    if kind == "translation":
        return Mesh(mesh.vertices + np.array([12.0, -3.0, 7.5]), mesh.faces)
    if kind == "scale":
        return Mesh(mesh.vertices * 23.0, mesh.faces)
    perm = np.random.default_rng(5).permutation(mesh.n_vertices)
    return Mesh(mesh.vertices[perm], np.argsort(perm)[mesh.faces])


@pytest.mark.parametrize("kind", ["rotation", "translation", "scale", "permutation"])
def test_bof_is_unchanged_by_rigid_motion_scale_and_vertex_order(shrec_mesh, random_rotation,
                                                                 base_and_vocabulary, kind):
    base, vocab = base_and_vocabulary
    moved = describe(_transformed(shrec_mesh, random_rotation(3), kind))
    assert moved.n_vertices == base.n_vertices
    # the HKS is the same set of per-vertex signatures (vertex order may differ after resampling)
    # (matched by nearest neighbour: sorting float rows would pair near-ties differently)
    nearest, match = cKDTree(moved.hks).query(base.hks)
    assert nearest.max() < 1e-4
    # the same keypoints, up to a point whose persistence or contrast sits on a filter threshold, where
    # rounding (a permuted eigen-solve) may tip it either way; vertex order leaking in would flip dozens
    flips = np.count_nonzero(base.keypoints != moved.keypoints[match])
    assert flips <= 2, f"{flips} keypoints differ"
    a, b = vocab.encode(base), vocab.encode(moved)
    # hard VQ may flip a vertex sitting on a Voronoi boundary: at most a few of ~1000 vertices
    assert l1_distance(a[None], b[None])[0, 0] <= 4 * 2.0 / base.n_vertices


def test_another_shape_is_far_away(base_and_vocabulary):
    base, vocab = base_and_vocabulary
    other = trimesh.creation.icosphere(subdivisions=3)
    far = describe(Mesh(np.asarray(other.vertices) * [0.6, 0.6, 2.0], np.asarray(other.faces)))
    assert l1_distance(vocab.encode(base)[None], vocab.encode(far)[None])[0, 0] > 0.5


def test_several_components_give_a_finite_description():
    a = trimesh.creation.icosphere(subdivisions=3)
    b = trimesh.creation.icosphere(subdivisions=3, radius=0.7)
    b.apply_translation([4.0, 0, 0])
    both = trimesh.util.concatenate([a, b])
    mesh = clean(Mesh(np.asarray(both.vertices), np.asarray(both.faces)))
    desc = describe(mesh, DescribeParams(k=60))
    assert np.all(np.isfinite(desc.hks))
    assert desc.eigenvalues[1] < 1e-8 < desc.eigenvalues[2]  # two zero eigenvalues, t_max from the third
    assert np.allclose(np.linalg.norm(desc.hks, axis=1), 1.0, atol=1e-5)


def test_description_round_trips_through_npz(tmp_path, shrec_mesh):
    desc = describe(shrec_mesh, DescribeParams(k=50))
    desc.save(tmp_path / "d.npz")
    again = ShapeDescription.load(tmp_path / "d.npz")
    assert np.array_equal(again.hks, desc.hks) and np.array_equal(again.keypoints, desc.keypoints)
    assert np.array_equal(again.eigenvalues, desc.eigenvalues) and again.input_vertices == desc.input_vertices
    assert np.isclose(again.weights.sum(), 1.0, atol=1e-5)  # lumped areas of the unit-area mesh


def test_fingerprint_names_every_parameter_that_changes_the_description():
    a = DescribeParams()
    assert a.fingerprint() == DescribeParams().fingerprint()
    assert a.fingerprint() != DescribeParams(k=200).fingerprint()
    assert a.fingerprint() != DescribeParams(target_vertices=0).fingerprint()
    assert a.fingerprint() != DescribeParams(smoothing=0).fingerprint()
    assert a.fingerprint() != DescribeParams(subdivision="loop").fingerprint()
    with pytest.raises(ValueError, match="subdivision"):
        DescribeParams(subdivision="butterfly")
