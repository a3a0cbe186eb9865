"""BoF + Shape-DNA fusion: L1 over the fused vector is the fused distance; scales; the vocabulary's use."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.baselines import shape_dna_of_mesh
from app.core.fusion import FusionScales, dna_vector, fit_scales, fuse, pairwise_l1
from app.core.mesh import Mesh
from app.core.pipeline import DescribeParams, ShapeDescription, describe
from app.core.vocabulary import EncodeParams, Vocabulary, l1_distance

WORDS = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]], np.float32)


def description(p: np.ndarray, eigenvalues: np.ndarray) -> ShapeDescription:
    """A stand-in whose Run 5 selection is p (n, 4) and whose spectrum is `eigenvalues`."""
    h = np.zeros((p.shape[0], 100), np.float32)
    h[:, [19, 39, 59, 79]] = p
    n = p.shape[0]
    return ShapeDescription(hks=h, weights=np.full(n, 1.0 / n, np.float32), keypoints=np.ones(n, bool),
                            eigenvalues=np.asarray(eigenvalues, float), input_vertices=n)


def test_l1_of_fused_vectors_is_the_fused_distance():
    rng = np.random.default_rng(0)
    scales = FusionScales(bof=0.4, dna=2.5, weight=0.7, count=5)
    bof_a, bof_b = rng.random(8), rng.random(8)
    dna_a, dna_b = rng.random(5) * 10, rng.random(5) * 10
    fa, fb = fuse(bof_a, dna_a, scales), fuse(bof_b, dna_b, scales)
    assert fa.shape == (13,) and fa.dtype == np.float32
    expected = np.abs(bof_a - bof_b).sum() / 0.4 + 0.7 * np.abs(dna_a - dna_b).sum() / 2.5
    assert l1_distance(fa[None], fb[None])[0, 0] == pytest.approx(expected, rel=1e-5)
    # weight 0: the ranking is the BoF's, scaled
    flat = FusionScales(bof=0.4, dna=2.5, weight=0.0, count=5)
    assert l1_distance(fuse(bof_a, dna_a, flat)[None], fuse(bof_b, dna_b, flat)[None])[0, 0] == (
        pytest.approx(np.abs(bof_a - bof_b).sum() / 0.4, rel=1e-5))
    with pytest.raises(ValueError, match="entries"):
        fuse(bof_a, dna_a[:4], scales)


def test_fit_scales_by_hand():
    bofs = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]])  # pairwise L1: 1, 3, 2 -> median 2
    dnas = np.array([[0.0], [4.0], [10.0]])  # 4, 10, 6 -> median 6
    scales = fit_scales(bofs, dnas, weight=0.5)
    assert scales == FusionScales(bof=2.0, dna=6.0, weight=0.5, count=1)
    # most pairs equal: the median is 0, the mean takes over (4 of 10 pairs at distance 3)
    same = np.array([[0.0], [0.0], [0.0], [0.0], [3.0]])
    assert fit_scales(same, same, 1.0).bof == pytest.approx(1.2)
    with pytest.raises(ValueError, match="pair up"):
        fit_scales(bofs, dnas[:2], 1.0)


def test_pair_sampling_is_deterministic_and_never_pairs_a_shape_with_itself():
    x = np.random.default_rng(1).random((300, 3))  # 44,850 pairs > 1,000: sampled
    d = pairwise_l1(x, max_pairs=1000)
    assert d.shape == (1000,) and (d > 0).all()
    assert np.array_equal(d, pairwise_l1(x, max_pairs=1000))
    full = pairwise_l1(x)  # all pairs
    assert full.shape == (300 * 299 // 2,)
    assert np.median(d) == pytest.approx(np.median(full), rel=0.1)


def test_scales_round_trip_and_validation():
    scales = FusionScales(bof=0.3, dna=1.5, weight=1.0, count=30)
    assert FusionScales.from_dict(scales.to_dict()) == scales
    with pytest.raises(ValueError):
        FusionScales(bof=0.0, dna=1.0, weight=1.0)


def test_dna_of_a_description_is_scale_invariant_and_equals_the_mesh_shape_dna(ellipsoid_mesh: Mesh):
    params = DescribeParams(k=40, m=20, target_vertices=0, smoothing=0, laplacian="cotangent")
    base = dna_vector(describe(ellipsoid_mesh, params), 30)
    scaled = Mesh(ellipsoid_mesh.vertices * 7.5 + 3.0, ellipsoid_mesh.faces)
    assert np.allclose(dna_vector(describe(scaled, params), 30), base, rtol=1e-6)
    # the description's unit-area eigenvalues give the Shape-DNA λ_i·A/i of the mesh as it is
    assert np.allclose(base, shape_dna_of_mesh(ellipsoid_mesh, 30), rtol=1e-5)


def training_set() -> list[ShapeDescription]:
    rng = np.random.default_rng(2)
    return [description(rng.random((6, 4)), np.concatenate([[0.0], np.sort(rng.random(40)) * 50 + i]))
            for i in range(6)]


def test_vocabulary_with_fusion_encodes_the_fused_vector_and_keeps_its_scales(tmp_path):
    descs = training_set()
    plain = Vocabulary(WORDS, run="run5", sigma=0.5)
    vocab = plain.with_fusion(descs, weight=0.5)
    scales = vocab.fusion
    assert scales is not None and scales.count == 30 and scales.weight == 0.5
    bofs = np.stack([plain.encode(d) for d in descs])
    assert scales.bof == pytest.approx(np.median(pairwise_l1(bofs)))
    d = descs[0]
    fused = vocab.encode(d)
    assert fused.shape == (vocab.dimension(),) == (3 + 30,)
    assert np.allclose(fused, fuse(plain.encode(d), dna_vector(d, 30), scales))
    # pure BoF stays an option, and a vocabulary without scales always serves it
    off = EncodeParams(fusion=False)
    assert vocab.dimension(off) == plain.dimension() == 3
    assert np.array_equal(vocab.encode(d, off), plain.encode(d))
    again = Vocabulary.load(vocab.save(tmp_path / "v"))
    assert again.fusion == scales and np.array_equal(again.encode(d), fused)
    # the scale is the median of BoFs encoded one way; the vocabulary says which
    assert again.metadata["encode"] == {
        "mode": "soft", "sigma_scale": 1.0, "keypoints_only": False, "area_weighted": True
    }
    by_count = EncodeParams(area_weighted=False)
    counted = plain.with_fusion(descs, by_count, weight=0.5)
    assert counted.metadata["encode"]["area_weighted"] is False
    assert counted.fusion.bof == pytest.approx(np.median(pairwise_l1(np.stack([plain.encode(x, by_count)
                                                                            for x in descs]))))


def test_fusion_uses_only_the_eigenvalues_every_training_shape_has():
    descs = training_set()
    short = description(np.zeros((3, 4)), np.arange(13.0))  # 12 non-zero eigenvalues
    vocab = Vocabulary(WORDS, run="run5", sigma=0.5).with_fusion([*descs, short])
    assert vocab.fusion is not None and vocab.fusion.count == 12 and vocab.dimension() == 15


# Fusion edge cases: fuse on batches and float32 input, pairwise_l1's
# exact and sampled pairs (uniform over the unordered pairs), the scale fallbacks and validation.


def test_fuse_keeps_a_batch_of_rows_apart():
    scales = FusionScales(bof=0.5, dna=2.0, weight=3.0, count=2)
    bof = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    dna = np.array([[2.0, 4.0], [6.0, 8.0]])
    out = fuse(bof, dna, scales)
    assert out.shape == (2, 5)
    assert np.array_equal(out, np.array([[2, 4, 6, 3, 6], [8, 10, 12, 9, 12]], np.float32))


def test_fuse_computes_in_double_precision_whatever_the_input_dtype():
    rng = np.random.default_rng(3)
    scales = FusionScales(bof=0.3, dna=1.7, weight=0.9, count=30)
    bof = rng.random((50, 40)).astype(np.float32)
    dna = (rng.random((50, 30)) * 10).astype(np.float32)
    exact = fuse(bof.astype(np.float64), dna.astype(np.float64), scales)
    assert np.array_equal(fuse(bof, dna, scales), exact)
    # the float32 result is the float64 one rounded once
    assert np.array_equal(exact[:, :40], (bof.astype(np.float64) / 0.3).astype(np.float32))


def test_pairwise_l1_is_exact_for_float32_and_small_integer_input():
    x = np.array([[16777216.0, 1.0], [0.0, 0.0]], np.float32)  # 2**24 + 1 is not a float32
    assert pairwise_l1(x).tolist() == [16777217.0]
    assert pairwise_l1(np.array([[0], [200]], np.uint8)).tolist() == [200.0]


def test_two_shapes_have_one_distance_and_one_shape_is_refused_in_words():
    assert pairwise_l1(np.array([[0.0, 1.0], [3.0, -1.0]])).tolist() == [5.0]
    with pytest.raises(ValueError, match=r"^a scale needs at least 2 shapes, got 1$"):
        pairwise_l1(np.zeros((1, 3)))


def test_all_pairs_are_taken_up_to_exactly_max_pairs_then_sampled():
    x = np.array([[1.0], [2.0], [4.0], [8.0], [16.0]])  # 5 shapes, 10 pairs
    i, j = np.triu_indices(5, k=1)
    assert np.array_equal(pairwise_l1(x, max_pairs=10), np.abs(x[i] - x[j]).ravel())
    assert pairwise_l1(x, max_pairs=9).shape == (9,)


def test_sampled_pairs_are_uniform_over_the_unordered_pairs_and_never_a_shape_with_itself():
    n = 50  # 1,225 pairs, 1,200 drawn per seed; x = 2**k: every pair has its own distance
    x = 2.0 ** np.arange(n)[:, None]
    i, j = np.triu_indices(n, k=1)
    pair_of = {float(x[b, 0] - x[a, 0]): (a, b) for a, b in zip(i, j, strict=True)}
    shapes, offsets = np.zeros(n), np.zeros(n // 2 + 1)
    for seed in range(20):
        d = pairwise_l1(x, max_pairs=1200, seed=seed)
        assert d.shape == (1200,) and (d > 0).all()
        for a, b in map(pair_of.__getitem__, d.tolist()):
            shapes[[a, b]] += 1
            offsets[min(b - a, n - (b - a))] += 1  # distance round the cycle 0..n-1
    draws = 20 * 1200
    assert np.allclose(shapes / draws, 2 / n, rtol=0.15)  # every shape as often as any other
    # each cyclic offset 1..24 has n pairs, offset 25 has n / 2: as often as the pairs are many
    assert np.allclose(offsets[1:-1] / draws, n / 1225, rtol=0.15)
    assert offsets[-1] / draws == pytest.approx(n / 2 / 1225, rel=0.25)


def test_identical_shapes_get_the_unit_scale():
    same = np.ones((4, 3))
    scales = fit_scales(same, same)
    assert scales.bof == 1.0 and scales.dna == 1.0


def test_fit_scales_refuses_a_flat_bof_array_even_if_the_counts_match():
    with pytest.raises(ValueError, match="pair up"):
        fit_scales(np.zeros(3), np.zeros((3, 2)))


def test_scale_validation_edges_and_message():
    FusionScales(bof=0.5, dna=0.5, weight=0.0, count=1)  # scales below 1 are fine
    with pytest.raises(ValueError, match=r"^fusion scales must be positive \(weight >= 0, count >= 1\): "):
        FusionScales(bof=1.0, dna=0.0, weight=1.0)


def test_scales_stored_without_a_count_read_back_with_the_default_30():
    assert FusionScales.from_dict({"bof": 2, "dna": 3, "weight": 1}) == FusionScales(2.0, 3.0, 1.0, 30)
