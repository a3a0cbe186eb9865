"""Vector quantisation (eqs. 5-6), the BoF integral (eqs. 7-8), L1 distance, and persistence."""

from __future__ import annotations

import itertools
import json
from datetime import datetime

import numpy as np
import pytest

from app.core.descriptor import select
from app.core.fusion import pairwise_l1
from app.core.pipeline import ShapeDescription
from app.core.spectrum import SpectrumError
from app.core.vocabulary import (
    VOCABULARY_FORMAT,
    EncodeParams,
    Vocabulary,
    l1_distance,
    params_dict,
    training_features,
)


def make_description(h: np.ndarray, keypoints=None, weights=None) -> ShapeDescription:
    n = h.shape[0]
    return ShapeDescription(
        hks=h.astype(np.float32),
        weights=np.full(n, 1.0 / n, np.float32) if weights is None else weights.astype(np.float32),
        keypoints=np.ones(n, bool) if keypoints is None else keypoints,
        eigenvalues=np.arange(5.0),
        input_vertices=n,
    )


def h_with_run5(p: np.ndarray) -> np.ndarray:
    """(n, 4) -> (n, 100) normalised-HKS stand-in whose Run 5 selection is exactly p."""
    h = np.zeros((p.shape[0], 100))
    h[:, [19, 39, 59, 79]] = p
    return h


WORDS = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]], np.float32)


def test_hard_vq_assigns_the_nearest_word_and_counts():
    vocab = Vocabulary(WORDS, run="run5", sigma=0.5)
    p = np.array([[0.1, 0, 0, 0], [0.9, 0.2, 0, 0], [0.2, 0.7, 0, 0], [0.8, 0, 0, 0]])
    per_vertex = EncodeParams(mode="hard", normalize=False, area_weighted=False)
    bof = vocab.encode(make_description(h_with_run5(p)), per_vertex)
    assert bof.tolist() == [1.0, 2.0, 1.0]  # eq. 8: Σ θ(x)
    assert np.allclose(vocab.encode(make_description(h_with_run5(p)),
                                    EncodeParams(mode="hard", area_weighted=False)), [0.25, 0.5, 0.25])


def test_soft_vq_rows_sum_to_one_and_tend_to_hard_as_sigma_shrinks():
    vocab = Vocabulary(WORDS, run="run5", sigma=1.0)
    p = np.array([[0.3, 0.1, 0, 0], [0.0, 0.8, 0.1, 0]])
    soft = vocab.quantize(p, EncodeParams(mode="soft"))
    assert np.allclose(soft.sum(axis=1), 1.0)
    # eq. 5 by hand for the first point: θ_i ∝ exp(-|p - p_i|² / 2σ²)
    d2 = ((p[0] - WORDS) ** 2).sum(axis=1)
    expected = np.exp(-d2 / 2.0) / np.exp(-d2 / 2.0).sum()
    assert np.allclose(soft[0], expected)
    sharp = vocab.quantize(p, EncodeParams(mode="soft", sigma_scale=1e-3))
    assert np.allclose(sharp, vocab.quantize(p, EncodeParams(mode="hard")), atol=1e-6)


def test_keypoints_only_and_area_weighting():
    vocab = Vocabulary(WORDS, run="run5", sigma=0.5)
    p = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]], float)
    d = make_description(h_with_run5(p), keypoints=np.array([True, True, False]),
                         weights=np.array([0.5, 0.25, 0.25]))
    by_count = EncodeParams(mode="hard", keypoints_only=True, area_weighted=False)
    assert np.allclose(vocab.encode(d, by_count), [0.5, 0.5, 0.0])
    assert np.allclose(vocab.encode(d, EncodeParams(mode="hard", keypoints_only=True)), [2 / 3, 1 / 3, 0.0])
    assert np.allclose(vocab.encode(d, EncodeParams(mode="hard", area_weighted=True)), [0.5, 0.25, 0.25])
    # the default is eq. 7, the integral over the surface: each vertex by its lumped area
    assert np.allclose(vocab.encode(d, EncodeParams(mode="hard")), [0.5, 0.25, 0.25])
    assert np.allclose(vocab.encode(d, EncodeParams(mode="hard", area_weighted=False)), [1 / 3, 1 / 3, 1 / 3])
    # soft VQ (the default) integrates θ(x) the same way: Σ_x w(x) θ(x) / Σ_x w(x)
    theta = vocab.quantize(p, EncodeParams())
    assert np.allclose(vocab.encode(d), np.array([0.5, 0.25, 0.25]) @ theta, atol=1e-6)
    assert np.allclose(vocab.encode(d, EncodeParams(keypoints_only=True)), (2 * theta[0] + theta[1]) / 3,
                       atol=1e-6)


def test_soft_vq_is_the_default_with_sigma_the_vocabulary_s_quantisation_distance():
    """Soft VQ is served (issue 11, round 7); σ = 1 × the vocabulary's median quantisation distance."""
    assert EncodeParams().mode == "soft" and EncodeParams().sigma_scale == 1.0
    vocab = Vocabulary(WORDS, run="run5", sigma=0.5)
    p = np.array([[0.45, 0.0, 0, 0]])  # nearly half-way between words 0 and 1
    theta = vocab.quantize(p)[0]
    # by hand: exp(-0.45² / 2σ²), exp(-0.55² / 2σ²), exp(-(0.45² + 1) / 2σ²), normalised
    e = np.exp(-np.array([0.2025, 0.3025, 1.2025]) / 0.5)
    assert np.allclose(theta, e / e.sum())
    # a descriptor that crosses the border moves its mass a little, not all of it (hard VQ: all)
    across = vocab.quantize(np.array([[0.55, 0.0, 0, 0]]))[0]
    assert abs(across[0] - theta[0]) < 0.2
    hard = EncodeParams(mode="hard")
    assert vocab.quantize(p, hard)[0, 0] - vocab.quantize(np.array([[0.55, 0.0, 0, 0]]), hard)[0, 0] == 1.0


def test_l1_distance_by_hand():
    a = np.array([[0.5, 0.5, 0.0]])
    b = np.array([[0.0, 0.5, 0.5], [0.5, 0.5, 0.0]])
    assert np.allclose(l1_distance(a, b), [[1.0, 0.0]])


def test_fit_finds_well_separated_clusters():
    rng = np.random.default_rng(0)
    centres = rng.random((8, 4)) * 10
    feats = np.concatenate([c + 0.01 * rng.normal(size=(50, 4)) for c in centres])
    vocab = Vocabulary.fit_features(feats, size=8, run="run5")
    matched = np.abs(vocab.centers[:, None, :] - centres[None]).sum(axis=2).min(axis=0)
    assert matched.max() < 0.05
    assert vocab.metadata["trained_on_descriptors"] == 400
    with pytest.raises(ValueError, match="distinct descriptors"):
        Vocabulary.fit_features(feats[:5], size=8, run="run5")


def test_save_load_round_trip_without_pickle(tmp_path):
    vocab = Vocabulary.fit_features(np.random.default_rng(1).random((300, 4)), size=16, run="run5")
    path = vocab.save(tmp_path / "v1")
    again = Vocabulary.load(path)
    assert np.array_equal(again.centers, vocab.centers) and again.run == "run5"
    assert again.sigma == pytest.approx(vocab.sigma)
    assert json.loads((path / "vocabulary.json").read_text())["size"] == 16
    assert path.stat().st_mode & 0o055 == 0o055  # readable by other users (e.g. a container's service user)
    with pytest.raises(FileExistsError):
        vocab.save(tmp_path / "v1")
    # a file with pickled objects is refused by the loader
    np.save(path / "centers.npy", np.array([object()], dtype=object), allow_pickle=True)
    with pytest.raises(ValueError):
        Vocabulary.load(path)


def test_the_shipped_vocabulary_is_fit_for_the_describe_defaults_and_fused():
    """A change of describe defaults without `make vocabulary` would ship words from another p(x) space."""
    from importlib import resources

    from app.core.pipeline import DescribeParams

    vocab = Vocabulary.load(str(resources.files("app") / "data" / "vocabulary" / "default"))
    assert vocab.metadata["describe"] == DescribeParams().fingerprint(), "refit it: make vocabulary"
    assert vocab.size == 64 and vocab.run == "run5"
    assert vocab.fusion is not None and vocab.dimension() == 64 + vocab.fusion.count
    assert vocab.dimension(EncodeParams(fusion=False)) == 64


def test_encoding_records_sigma_for_soft_bofs_only():
    """A vocabulary's fusion scale is the median of BoFs encoded one way; σ changes soft BoFs only."""
    assert EncodeParams(mode="soft", sigma_scale=0.7).encoding() == {
        "mode": "soft", "sigma_scale": 0.7, "keypoints_only": False, "area_weighted": True
    }
    assert EncodeParams(mode="hard", sigma_scale=0.7).encoding() == {
        "mode": "hard", "keypoints_only": False, "area_weighted": True
    }


def test_a_recorded_encoding_is_read_back_and_compared_with_the_fusion_scale_s():
    soft = EncodeParams(mode="soft", sigma_scale=0.7, fusion=False)
    # with_encoding takes what encoding() recorded, and keeps what it does not name (fusion)
    hard = EncodeParams(mode="hard")
    assert hard.with_encoding(soft.encoding()) == EncodeParams(mode="soft", sigma_scale=0.7)
    assert EncodeParams(fusion=False).with_encoding({"mode": "hard"}) == EncodeParams(mode="hard",
                                                                                      fusion=False)
    meta = {"encode": EncodeParams(mode="hard").encoding(), "fusion": {"bof": 1.0, "dna": 1.0, "weight": 1.0}}
    fused = Vocabulary(WORDS, run="run5", sigma=0.5, metadata=meta)
    assert fused.fusion_encoding_changes(EncodeParams(mode="hard")) == {}
    assert fused.fusion_encoding_changes(EncodeParams()) == {"mode": ("hard", "soft")}
    assert Vocabulary(WORDS, run="run5", metadata={"encode": meta["encode"]}).fusion_encoding_changes(
        EncodeParams()) == {}  # no fusion scale: nothing weighted off


# Vocabulary.fit, training_features, describe_meta, the fit metadata and with_fusion's edges, called
# directly.


def description(p: np.ndarray, keypoints=None, eigenvalues=None, column: int = 19) -> ShapeDescription:
    """A stand-in whose Run 5 selection (HKS columns 19, 39, 59, 79) is p (n, 4); Run 1 is column 19."""
    n = p.shape[0]
    h = np.zeros((n, 100), np.float32)
    h[:, [column, column + 20, column + 40, column + 60]] = p
    return ShapeDescription(
        hks=h,
        weights=np.full(n, 1.0 / n, np.float32),
        keypoints=np.ones(n, bool) if keypoints is None else np.asarray(keypoints),
        eigenvalues=np.arange(5.0) if eigenvalues is None else np.asarray(eigenvalues, float),
        input_vertices=n,
    )


def clusters(seed: int, n: int = 40) -> np.ndarray:
    """(n, 4) points around 4 well-separated centres, 4 apart."""
    rng = np.random.default_rng(seed)
    centres = np.eye(4) * 4.0
    return centres[np.arange(n) % 4] + 0.01 * rng.normal(size=(n, 4))


def test_training_features_stack_the_keypoints_of_every_description_in_order():
    a, b = clusters(0, 6), clusters(1, 5)
    da = description(a, keypoints=[True, False, True, False, False, True])
    db = description(b, keypoints=[False, True, False, False, True])
    assert np.array_equal(
        training_features([da, db]), np.concatenate([a[[0, 2, 5]], b[[1, 4]]]).astype(np.float32)
    )
    everything = training_features([da, db], keypoints_only=False)
    assert np.array_equal(everything, np.concatenate([a, b]).astype(np.float32))


def test_training_features_select_the_run():
    d = description(np.random.default_rng(0).random((3, 4)))
    for run in ("run1", "run2", "run5"):
        assert np.array_equal(training_features([d], run=run), select(d.hks, run))
    with pytest.raises(ValueError, match="^no descriptions to fit a vocabulary on$"):
        training_features([])


def test_fit_clusters_the_keypoints_with_its_size_run_seed_and_metadata():
    p = clusters(0, 40)
    keep = np.arange(40) < 32  # the last 8 are not keypoints: k-means never sees them
    far = p.copy()
    far[32:] += 100.0
    descs = [description(far, keypoints=keep), description(clusters(1, 40))]
    vocab = Vocabulary.fit(descs, size=4, run="run5", seed=3, metadata={"note": "x", "seed": 99})
    assert vocab.centers.shape == (4, 4) and vocab.centers.dtype == np.float32 and vocab.run == "run5"
    assert np.abs(vocab.centers).max() < 5  # no word out at the +100 non-keypoints
    assert sorted(np.round(vocab.centers).argmax(axis=1).tolist()) == [0, 1, 2, 3]
    meta = vocab.metadata
    assert meta["trained_on_descriptors"] == 72 and meta["size"] == 4 and meta["run"] == "run5"
    assert meta["dimension"] == 4 and meta["format"] == VOCABULARY_FORMAT
    assert meta["note"] == "x" and meta["seed"] == 99  # the caller's metadata wins
    every = Vocabulary.fit(descs, size=4, seed=3, keypoints_only=False)
    assert every.metadata["trained_on_descriptors"] == 80 and every.metadata["seed"] == 3
    assert np.abs(every.centers).max() > 50  # now the far points make a word


def test_fit_is_deterministic_for_a_seed():
    descs = [description(np.random.default_rng(s).random((60, 4))) for s in range(2)]
    a = Vocabulary.fit(descs, size=6, seed=1)
    assert np.array_equal(a.centers, Vocabulary.fit(descs, size=6, seed=1).centers)
    assert not np.array_equal(a.centers, Vocabulary.fit(descs, size=6, seed=2).centers)


def test_fit_metadata_records_the_inertia_sigma_and_time():
    feats = clusters(4, 80)
    vocab = Vocabulary.fit_features(feats, size=4, run="run5", seed=0)
    d2 = ((feats[:, None, :] - vocab.centers[None].astype(np.float64)) ** 2).sum(axis=2).min(axis=1)
    assert vocab.metadata["inertia"] == pytest.approx(d2.sum(), rel=1e-4)
    assert vocab.sigma == pytest.approx(np.median(np.sqrt(d2)), rel=1e-3)
    created = datetime.fromisoformat(vocab.metadata["created_at"])
    assert created.tzinfo is not None and abs((datetime.now(created.tzinfo) - created).total_seconds()) < 60


def test_sigma_falls_back_to_the_mean_then_to_one():
    """Most descriptors exactly on their word: the median distance is 0 and sigma is the mean distance;
    every one on its word: 1. (16 points with dyadic coordinates: k-means' centring stays exact.)"""
    words = np.repeat(np.eye(4)[1:], 4, axis=0)
    feats = np.concatenate([words, [[1, 0, 0, 0], [1, 0, 0, 0], [1, 0.5, 0, 0], [1, -0.5, 0, 0]]])
    assert Vocabulary.fit_features(feats, size=4, run="run5").sigma == 2 * 0.5 / 16
    assert Vocabulary.fit_features(np.repeat(np.eye(4), 3, axis=0), size=4, run="run5").sigma == 1.0


def test_fit_features_refuses_the_wrong_width_in_words():
    with pytest.raises(ValueError, match=r"features must be \(N, 4\) for run5, got \(10, 3\)"):
        Vocabulary.fit_features(np.zeros((10, 3)), size=2, run="run5")
    with pytest.raises(ValueError, match=r"features must be \(N, 4\) for run5, got \(10,\)"):
        Vocabulary.fit_features(np.zeros(10), size=2, run="run5")
    with pytest.raises(ValueError, match="^3 distinct descriptors cannot make 4 words$"):
        Vocabulary.fit_features(np.repeat(np.eye(4)[:3], 5, axis=0), size=4, run="run5")
    assert Vocabulary.fit_features(np.eye(4), size=4, run="run5").size == 4  # exactly enough


def test_describe_meta_is_the_metadata_with_the_live_run_sigma_and_size():
    vocab = Vocabulary(WORDS, run="run5", sigma=0.25, metadata={"size": 99, "run": "old", "note": "n"})
    assert vocab.describe_meta() == {"size": 3, "run": "run5", "sigma": 0.25, "note": "n"}
    assert vocab.metadata == {"size": 99, "run": "old", "note": "n"}  # not changed in place


def test_with_fusion_needs_two_shapes_and_keeps_the_metadata():
    plain = Vocabulary(WORDS, run="run5", sigma=0.5, metadata={"note": "kept"})
    one = [description(clusters(0, 4), eigenvalues=[0.0, 2.0, 3.0])]
    with pytest.raises(ValueError, match="^fusion scales need at least 2 training shapes$"):
        plain.with_fusion(one)
    two = [*one, description(clusters(1, 4) + 0.5, eigenvalues=[0.0, 1.0])]  # one non-zero eigenvalue
    fused = plain.with_fusion(two)
    assert fused.fusion is not None and fused.fusion.count == 1  # c = 1 is enough
    assert fused.metadata["note"] == "kept" and "fusion" not in plain.metadata
    flat = [*one, description(clusters(1, 4), eigenvalues=[0.0, 0.0])]  # no non-zero eigenvalue
    with pytest.raises(SpectrumError, match="no non-zero eigenvalue"):
        plain.with_fusion(flat)


def test_with_fusion_scales_the_bof_encoded_with_the_params():
    """The BoF scale is the median pairwise L1 of the training BoFs as `params` encode them."""
    rng = np.random.default_rng(5)
    descs = [
        description(rng.random((8, 4)), keypoints=rng.random(8) < 0.5, eigenvalues=np.arange(6.0) * (i + 1))
        for i in range(5)
    ]
    plain = Vocabulary(WORDS, run="run5", sigma=0.5)
    params = EncodeParams(keypoints_only=True, mode="soft")
    scales = plain.with_fusion(descs, params).fusion
    bofs = np.stack([plain.bof(d, params) for d in descs])
    assert scales is not None and scales.bof == pytest.approx(np.median(pairwise_l1(bofs)))
    default = np.stack([plain.bof(d) for d in descs])
    assert not np.isclose(np.median(pairwise_l1(default)), scales.bof)


def test_fit_defaults_to_64_words_seed_0_and_passes_the_run():
    rng = np.random.default_rng(7)
    descs = [description(rng.random((80, 4))) for _ in range(2)]
    vocab = Vocabulary.fit(descs)
    assert vocab.size == 64 and vocab.metadata["seed"] == 0
    assert np.array_equal(vocab.centers, Vocabulary.fit(descs, seed=0).centers)
    run2 = Vocabulary.fit(descs, size=8, run="run2")
    assert run2.run == "run2" and run2.centers.shape == (8, 5) and run2.metadata["dimension"] == 5
    assert Vocabulary.fit_features(rng.random((70, 4)), run="run5").size == 64


def test_bof_uses_the_vocabulary_run_the_mode_and_float32():
    p = np.array([[0.1, 0, 0, 0], [0.9, 0.2, 0, 0], [0.2, 0.7, 0, 0]])
    d = description(p, column=0)  # run1 reads h_95..h_100 (zero here); a run5 read would see p
    run1 = Vocabulary(np.eye(6, dtype=np.float32)[:3], run="run1", sigma=0.5)
    expected = run1.quantize(select(d.hks, "run1")).mean(axis=0)
    assert np.allclose(run1.encode(d), expected)
    vocab = Vocabulary(WORDS, run="run5", sigma=0.5)
    d5 = description(p)
    soft = EncodeParams(mode="soft")
    out = vocab.encode(d5, soft)
    hard = EncodeParams(mode="hard")
    assert out.dtype == np.float32 and vocab.encode(d5, hard).dtype == np.float32
    assert np.allclose(out, vocab.quantize(p, soft).mean(axis=0), atol=1e-6)
    assert not np.allclose(out, vocab.encode(d5, hard))  # soft is not hard


def test_bof_normalises_by_the_total_weight_and_an_empty_selection_is_zero():
    vocab = Vocabulary(WORDS, run="run5", sigma=0.5)
    p = np.array([[0, 0, 0, 0], [1, 0, 0, 0]], float)
    half = description(p, keypoints=[False, False])
    half = ShapeDescription(
        hks=half.hks,
        weights=np.array([0.125, 0.375], np.float32),
        keypoints=half.keypoints,
        eigenvalues=half.eigenvalues,
        input_vertices=2,
    )
    assert np.allclose(vocab.encode(half, EncodeParams(mode="hard", area_weighted=True)), [0.25, 0.75, 0.0])
    nothing = vocab.encode(half, EncodeParams(keypoints_only=True))
    assert np.array_equal(nothing, np.zeros(3, np.float32))  # no keypoint: zero, not 0/0


def test_soft_width_is_sigma_scale_times_the_vocabulary_sigma():
    vocab = Vocabulary(WORDS, run="run5", sigma=0.5)
    p = np.array([[0.3, 0.1, 0, 0]])
    theta = vocab.quantize(p, EncodeParams(mode="soft", sigma_scale=3.0))
    d2 = ((p[0] - WORDS) ** 2).sum(axis=1)
    width = 3.0 * 0.5
    expected = np.exp(-d2 / (2 * width**2))
    assert np.allclose(theta[0], expected / expected.sum())
    with pytest.raises(ValueError, match=r"^unknown quantisation mode 'fuzzy'; use 'hard' or 'soft'$"):
        vocab.quantize(p, EncodeParams(mode="fuzzy"))


def test_a_fused_vector_has_as_many_dna_values_as_the_scales():
    plain = Vocabulary(WORDS, run="run5", sigma=0.5)
    two = [
        description(clusters(0, 4), eigenvalues=[0.0, 2.0, 3.0]),
        description(clusters(1, 4) + 0.5, eigenvalues=[0.0, 1.0]),
    ]
    fused = plain.with_fusion(two)
    assert fused.encode(two[0]).shape == (fused.dimension(),) == (4,)


def test_params_dict_is_every_encode_setting():
    assert params_dict(EncodeParams(mode="soft", sigma_scale=2.0)) == {
        "mode": "soft",
        "sigma_scale": 2.0,
        "keypoints_only": False,
        "area_weighted": True,
        "normalize": True,
        "fusion": True,
    }


def test_fit_features_default_seed_and_distinct_at_12_decimals():
    feats = np.random.default_rng(8).random((40, 4))
    assert np.array_equal(
        Vocabulary.fit_features(feats, size=5).centers, Vocabulary.fit_features(feats, size=5, seed=0).centers
    )
    near = np.array([[0.1, 0, 0, 0], [0.1 + 3e-13, 0, 0, 0], [0.5, 0, 0, 0]])  # equal to 12 decimals
    with pytest.raises(ValueError, match="^2 distinct descriptors cannot make 3 words$"):
        Vocabulary.fit_features(near, size=3, run="run5")


def test_save_makes_missing_parents_and_load_keeps_run_dtype_and_checks(tmp_path):
    vocab = Vocabulary.fit_features(np.random.default_rng(2).random((40, 5)), size=4, run="run2")
    path = vocab.save(tmp_path / "a" / "b" / "v1")
    again = Vocabulary.load(path)
    assert again.run == "run2" and again.centers.dtype == np.float32
    with pytest.raises(FileExistsError, match=r"v1 exists: vocabularies are immutable$"):
        vocab.save(path)
    meta = json.loads((path / "vocabulary.json").read_text())
    (path / "vocabulary.json").write_text(
        json.dumps(dict(meta, fusion={"bof": -1.0, "dna": 1.0, "weight": 1.0}))
    )
    with pytest.raises(ValueError, match="fusion scales must be positive"):
        Vocabulary.load(path)  # a broken fusion entry fails at load, not at the first query
    (path / "vocabulary.json").write_text(json.dumps(dict(meta, size=5)))
    with pytest.raises(ValueError, match=r"is inconsistent: centers \(4, 5\)$"):
        Vocabulary.load(path)


def test_float32_features_are_clustered_in_float64():
    feats = np.random.default_rng(11).random((60, 4)).astype(np.float32)
    a = Vocabulary.fit_features(feats, size=5)
    b = Vocabulary.fit_features(feats.astype(np.float64), size=5)
    np.testing.assert_array_equal(a.centers, b.centers)
    assert a.sigma == b.sigma and a.metadata["inertia"] == b.metadata["inertia"]


def test_squared_distances_are_taken_in_float64_whatever_the_input_dtype():
    from app.core.vocabulary import _squared_distances

    rng = np.random.default_rng(12)
    p, c = rng.random((50, 4)).astype(np.float32), rng.random((7, 4)).astype(np.float32)
    np.testing.assert_array_equal(
        _squared_distances(p, c), _squared_distances(p.astype(np.float64), c.astype(np.float64))
    )


def test_save_writes_beside_the_target_under_a_hidden_name_then_renames(tmp_path, monkeypatch):
    import os

    renames: list[tuple[str, str]] = []
    real = os.rename

    def spy(src, dst):
        renames.append((str(src), str(dst)))
        real(src, dst)

    monkeypatch.setattr(os, "rename", spy)
    vocab = Vocabulary(centers=WORDS, run="run5")
    path = vocab.save(tmp_path / "vocabularies" / "v7")
    [(src, dst)] = renames
    assert dst == str(path)
    assert os.path.dirname(src) == str(tmp_path / "vocabularies")  # the same directory: an atomic rename
    assert os.path.basename(src).startswith(".v7.")  # hidden while incomplete


# Vocabulary.fit_features restarts k-means.
#
# One k-means++ run can seed two centres in one cluster and leave another without one: a local optimum.
# The vocabulary keeps the best of several seeded runs, so on well-separated clusters it finds the
# clustering a single run often misses.


def nine_clusters() -> tuple[np.ndarray, float]:
    """(N, 4) points around 9 centres 4 apart on a grid, spread 0.5, alternately 6 and 60 points (small
    clusters next to big ones are what a k-means++ seeding misses), and the inertia of the true
    partition: with clusters this far apart it is the optimum."""
    rng = np.random.default_rng(0)
    centres = np.zeros((9, 4))
    centres[:, :2] = 4.0 * np.array(list(itertools.product(range(3), repeat=2)))
    sizes = [60 if i % 2 else 6 for i in range(9)]
    points = [c + 0.5 * rng.normal(size=(s, 4)) for c, s in zip(centres, sizes, strict=True)]
    optimum = sum(float(((p - p.mean(axis=0)) ** 2).sum()) for p in points)
    return np.concatenate(points), optimum


def test_the_vocabulary_is_the_best_of_several_k_means_runs():
    """With one k-means++ run per fit, 9 of these 20 seeds end in a local optimum (scikit-learn 1.9); the
    best of 4 runs misses only if all 4 do (1 seed of 20; the best of 5: none). Allowing 4 misses keeps
    the test independent of scikit-learn's exact random streams: were each run to miss with probability
    0.45, the best of 4 would miss 5 or more of 20 about once in 900, one run 4 or fewer about once in 50."""
    features, optimum = nine_clusters()
    inertias = [Vocabulary.fit_features(features, size=9, run="run5", seed=seed).metadata["inertia"]
                for seed in range(20)]
    assert min(inertias) >= optimum * (1 - 1e-9)  # nothing beats the true partition
    found = sum(inertia <= optimum * (1 + 1e-9) for inertia in inertias)
    assert found >= 16, inertias
