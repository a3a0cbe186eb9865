"""p(x) selections of Table 1."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.descriptor import RUNS, dimension, select


@pytest.mark.parametrize(("run", "d"), [("run1", 6), ("run2", 5), ("run3", 19), ("run4", 9), ("run5", 4)])
def test_dimensions_match_table_1(run, d):
    h = np.random.default_rng(0).random((3, 100))
    assert dimension(run) == d and select(h, run).shape == (3, d)


def test_runs_pick_the_1_based_positions_of_table_1():
    h = np.tile(np.arange(1, 101, dtype=float), (2, 1))  # h_i = i
    assert select(h, "run5")[0].tolist() == [20, 40, 60, 80]
    assert select(h, "run1")[0].tolist() == [95, 96, 97, 98, 99, 100]
    assert select(h, "run3")[0, [0, -1]].tolist() == [5, 95]
    assert select(h, "run4")[0, [0, -1]].tolist() == [10, 90]


def test_run2_statistics():
    h = np.array([[1.0, 2.0, 3.0, 10.0]])
    assert np.allclose(select(h, "run2")[0], [1.0, 10.0, 4.0, 2.5, np.std([1, 2, 3, 10])])


def test_unknown_run_is_refused():
    with pytest.raises(ValueError, match="unknown descriptor run"):
        select(np.ones((1, 100)), "run9")
    assert len(RUNS) == 5


# p(x) for an HKS with fewer than 100 time samples: an early position that
# rounds to before the first sample reads the first one, never wraps around to the last.


def test_a_position_before_the_first_sample_reads_the_first():
    h = np.arange(10.0)[None, :]  # m = 10: run3's position 5 of 100 rounds to sample 0
    assert select(h, "run3")[0, 0] == 0.0
    assert select(h, "run3").shape == (1, 19) and select(h, "run3")[0, -1] == 9.0


def test_an_unknown_run_is_refused_naming_the_runs():
    with pytest.raises(
        ValueError, match=r"^unknown descriptor run 'run9'; use one of run1, run2, run3, run4, run5$"
    ):
        select(np.zeros((1, 100)), "run9")
