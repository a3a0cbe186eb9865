"""A keypoint is a *strict* 2-ring maximum (issue 15 item 8): equal neighbouring values make none.

The existing definition test only checks that every detected vertex beats its ring somewhere, which
`>=` also satisfies. Here a plateau (two neighbouring vertices sharing the top value, and a flat field
around them) must yield no maximum at all, with the filter off and on.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.core.keypoints import KeypointFilter, detect


def _grid(k: int) -> np.ndarray:
    """(2 (k-1)^2, 3) int64 faces of a k x k vertex grid, vertex (r, c) at index r * k + c."""
    faces = []
    for r in range(k - 1):
        for c in range(k - 1):
            a, b, d, e = r * k + c, r * k + c + 1, (r + 1) * k + c, (r + 1) * k + c + 1
            faces += [(a, b, e), (a, e, d)]
    return np.asarray(faces, dtype=np.int64)


K = 7
FACES = _grid(K)
CENTRE = 3 * K + 3


@pytest.mark.parametrize("enabled", [False, True])
def test_a_plateau_of_two_neighbours_is_no_maximum(enabled: bool) -> None:
    hks = np.zeros((K * K, 2))  # (n, m): flat everywhere ...
    hks[[CENTRE, CENTRE + 1]] = 1.0  # ... but two neighbouring vertices share the top value
    mask = detect(hks, FACES, KeypointFilter(enabled=enabled))
    assert mask.shape == (K * K,)
    assert not mask.any(), f"plateau vertices taken as maxima: {np.flatnonzero(mask)}"


@pytest.mark.parametrize("enabled", [False, True])
def test_a_single_peak_is_the_only_maximum(enabled: bool) -> None:
    # the control: the same field with one vertex slightly higher has exactly that maximum
    hks = np.zeros((K * K, 2))
    hks[[CENTRE, CENTRE + 1]] = 1.0
    hks[CENTRE, 0] = 1.0 + 1e-9
    mask = detect(hks, FACES, KeypointFilter(enabled=enabled, min_contrast=0.0, min_persistence=0.0))
    assert np.flatnonzero(mask).tolist() == [CENTRE]
