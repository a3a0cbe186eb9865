"""benchmarks.partial_served: the stratified sample, and that a piece is ranked by the service's code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.core.partial import LocalSignature
from app.core.partial_match import CAP, match_many
from app.core.pipeline import LOCAL, ShapeDescription
from app.datasets.folder import LabelledFile
from app.services import partial as partial_mod
from benchmarks.partial_served import Served, calibration_lines, full_ranking, sample


def _rows(labels: list[str]) -> list[LabelledFile]:
    return [LabelledFile(Path(f"/x/{i}.obj"), label) for i, label in enumerate(labels)]


def test_sample_takes_per_class_the_first_rows_of_the_split_in_folder_order():
    rows = _rows(["a"] * 8 + ["b"] * 8 + ["c"] * 2)  # indices 0, 6, 12 are the picking split
    held = sample(rows, 3, "held")
    assert held == [1, 2, 3, 8, 9, 10, 16, 17]
    assert all(i % 6 for i in held)
    assert sample(rows, 3, "pick") == [0, 6, 12]  # a: 0 and 6; b: 12; c: none
    assert sample(rows, 1, "pick") == [0, 12]


def test_full_ranking_puts_the_head_first_then_the_rest_in_global_order():
    order = np.array([4, 2, 0, 3, 1])
    assert full_ranking(np.array([3, 4]), order).tolist() == [3, 4, 2, 0, 1]


def _signature(rng: np.random.Generator, width: int, rim: float, points: int = 12) -> LocalSignature:
    slopes = (-0.5 - 0.3 * rng.random((points, width))).astype(np.float32)
    return LocalSignature(slopes=slopes, area=np.full(points, 1 / points, np.float32),
                          valid=np.full(points, width, np.int16), rim=rim,
                          vertex=np.arange(points, dtype=np.int32))


def _description(local: LocalSignature) -> ShapeDescription:
    return ShapeDescription(hks=np.zeros((1, 1), np.float32), weights=np.ones(1, np.float32),
                            keypoints=np.zeros(1, bool), eigenvalues=np.zeros(2), input_vertices=0,
                            local=local)


def test_a_piece_is_ordered_by_the_service_score_of_every_model():
    rng = np.random.default_rng(3)
    models = [_signature(rng, LOCAL.slopes, 0.0) for _ in range(6)]
    query = _signature(rng, LOCAL.slopes + LOCAL.shifts - 1, 1.0)
    query.slopes[:, :LOCAL.slopes] = models[4].slopes + 0.01  # close to model 4 at scale 1
    served = Served(np.zeros((6, 3)), list(models))
    desc = _description(query)
    order = np.array([5, 3, 1, 0, 2, 4])
    ranked, hits = served.rank(desc, order)
    scores = [m.score for m in match_many(query, models, LOCAL, mutual=True)]
    assert ranked.tolist() == sorted(range(6), key=lambda j: (scores[j], order.tolist().index(j)))
    assert ranked[0] == 4
    assert all(h.partial and h.forward is not None for h in hits)
    assert len(served.seconds) == 1
    found = match_many(query, models, LOCAL, mutual=True)
    alt = served.alternatives()  # other scores of the same matches, the same candidates
    position = order.tolist().index
    assert alt["distance alone"].tolist() == sorted(range(6), key=lambda j: (found[j].distance, position(j)))
    assert alt["mutual 1 (before)"].tolist() == sorted(
        range(6), key=lambda j: (found[j].distance - CAP * found[j].mutual, position(j)))
    assert served.last[1][0].mutual > 0  # the mutual share was computed for the "before" ranking


def test_a_model_without_signature_follows_the_scored_ones():
    rng = np.random.default_rng(4)
    models: list[LocalSignature | None] = [_signature(rng, LOCAL.slopes, 0.0) for _ in range(3)]
    models[0] = None
    query = _signature(rng, LOCAL.slopes + LOCAL.shifts - 1, 1.0)
    desc = _description(query)
    ranked, _ = Served(np.zeros((3, 3)), models).rank(desc, np.array([0, 1, 2]))
    assert ranked[-1] == 0
    assert partial_mod.local_of.__module__ == "app.services.partial"  # the patch is undone


def test_calibration_lines_read_the_kept_share_bands():
    own = np.array([[0.62, 0.8, 0.5, 0.6], [0.66, 0.9, 0.6, 0.7], [0.81, 1.0, 0.8, 0.8]])
    lines = calibration_lines(own)
    assert "forward 0.900" in lines[0] and "|scale - kept| 0.023" in lines[0]
    assert [line.split(":")[0].strip() for line in lines[1:]] == ["kept 0.60-0.65", "kept 0.65-0.70",
                                                                   "kept 0.80-0.85"]
    assert calibration_lines(own[:1]) == []


@pytest.mark.parametrize("split", ["held", "pick"])
def test_sample_never_mixes_the_splits(split):
    rows = _rows([c for c in "abcde" for _ in range(20)])
    chosen = sample(rows, 4, split)
    assert len(chosen) == 20 if split == "held" else len(chosen) <= 20
    assert all((i % 6 == 0) == (split == "pick") for i in chosen)
