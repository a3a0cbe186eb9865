"""pytest plugin for `make mutate`: run a mutant's tests quickest first.

mutmut 3 runs, for each mutant, every selected test that reached the mutated function, with `-x`, in
the order of a Python set (arbitrary). A mutant in spectrum.py is reached by a 0.02 s contract test and
by a 20 s end-to-end describe; killed by the first, it may still wait for the second. Ordering by the
durations mutmut recorded (mutants/mutmut-stats.json) changes which failing test stops the run, never
whether one fails: every test still runs for a survivor. Loaded only by `[tool.mutmut]`'s pytest args
(`-p tools.mutmut_fastest_first`); without the stats file (the first stats run) the order stays.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

STATS = Path("mutmut-stats.json")  # mutmut runs pytest inside mutants/


def durations(stats: Path = STATS) -> dict[str, float]:
    """Recorded call durations by test node id ({} when there is no readable stats file)."""
    try:
        return dict(json.loads(stats.read_text())["duration_by_test"])
    except (OSError, ValueError, KeyError, TypeError):
        return {}


def fastest_first(items: list, seconds: dict[str, float]) -> list:
    """Items by recorded duration, quickest first; unknown ones (new tests) first; ties keep their order."""
    return sorted(items, key=lambda item: seconds.get(item.nodeid, 0.0))


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(items: list) -> None:
    seconds = durations()
    if seconds:
        items[:] = fastest_first(items, seconds)
