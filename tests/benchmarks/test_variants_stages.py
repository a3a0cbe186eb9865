"""benchmarks/variants_stages.py: its timer counts every call, under the label it is given."""

from __future__ import annotations

import types

from benchmarks.variants_stages import Stages


def test_wrap_counts_calls_by_label_and_keeps_results() -> None:
    module = types.SimpleNamespace(square=lambda x, points=None: x * x)
    stages = Stages()
    stages.wrap(module, "square", lambda a, k: "small" if k.get("points") else "full")  # type: ignore[arg-type]
    assert [module.square(3), module.square(4, points=8), module.square(5, points=8)] == [9, 16, 25]
    assert stages.calls == {"full": 1, "small": 2}
    assert all(s >= 0.0 for s in stages.seconds.values())
    stages.add("lookup", 0.5, 3)
    assert {r["stage"]: r["calls"] for r in stages.rows()} == {"full": 1, "small": 2, "lookup": 3}
