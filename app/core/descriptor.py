"""The point descriptor p(x): a subset of the normalised HKS h(x) (the paper's Table 1)."""

from __future__ import annotations

import numpy as np

# 1-based positions in h(x) = (h_1, ..., h_100), exactly as Table 1 writes them
RUN_POSITIONS: dict[str, list[int]] = {
    "run1": [95, 96, 97, 98, 99, 100],
    "run3": list(range(5, 96, 5)),
    "run4": list(range(10, 91, 10)),
    "run5": [20, 40, 60, 80],
}
RUNS: tuple[str, ...] = ("run1", "run2", "run3", "run4", "run5")
DEFAULT_RUN = "run5"


def dimension(run: str) -> int:
    """d, the length of p(x) for a run."""
    _check(run)
    return 5 if run == "run2" else len(RUN_POSITIONS[run])


def select(h: np.ndarray, run: str = DEFAULT_RUN) -> np.ndarray:
    """(n, m) normalised HKS -> (n, d) p(x).

    Positions are given for m = 100 as in the paper; for another m they are rescaled to the same
    relative place on the time axis.
    """
    _check(run)
    h = np.asarray(h)
    m = h.shape[1]
    if run == "run2":
        return np.stack(
            [h.min(axis=1), h.max(axis=1), h.mean(axis=1), np.median(h, axis=1), h.std(axis=1)], axis=1
        )
    positions = np.asarray(RUN_POSITIONS[run])
    idx = np.clip(np.round(positions * m / 100.0).astype(int) - 1, 0, m - 1)
    return h[:, idx]


def _check(run: str) -> None:
    if run not in RUNS:
        raise ValueError(f"unknown descriptor run {run!r}; use one of {', '.join(RUNS)}")
