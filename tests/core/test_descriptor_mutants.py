"""p(x) for an HKS with fewer than 100 time samples (issue 15 mutation pass): an early position that
rounds to before the first sample reads the first one, never wraps around to the last."""

from __future__ import annotations

import numpy as np
import pytest

from app.core.descriptor import select


def test_a_position_before_the_first_sample_reads_the_first():
    h = np.arange(10.0)[None, :]  # m = 10: run3's position 5 of 100 rounds to sample 0
    assert select(h, "run3")[0, 0] == 0.0
    assert select(h, "run3").shape == (1, 19) and select(h, "run3")[0, -1] == 9.0


def test_an_unknown_run_is_refused_naming_the_runs():
    with pytest.raises(
        ValueError, match=r"^unknown descriptor run 'run9'; use one of run1, run2, run3, run4, run5$"
    ):
        select(np.zeros((1, 100)), "run9")
