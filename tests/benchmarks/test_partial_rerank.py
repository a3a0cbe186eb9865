"""benchmarks.partial_rerank's average precision, by hand."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.partial_rerank import average_precision


def test_average_precision_by_hand():
    ranked = np.array(["a", "b", "a", "c"])
    assert average_precision(ranked, "a", 2) == pytest.approx((1 / 1 + 2 / 3) / 2)
    # a relevant model the ranking never reaches counts as precision 0
    assert average_precision(ranked, "a", 3) == pytest.approx((1 / 1 + 2 / 3) / 3)
    assert average_precision(ranked, "z", 1) == 0.0
    assert np.isnan(average_precision(ranked, "z", 0))
