"""Vector quantisation (eqs. 5-6), the BoF integral (eqs. 7-8), L1 distance, and persistence."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.core.pipeline import ShapeDescription
from app.core.vocabulary import EncodeParams, Vocabulary, l1_distance


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
