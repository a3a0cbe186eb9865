"""Test-only: hold a real server's vocabulary fit at a barrier, so a kill lands mid-rebuild for sure.

Put this directory on PYTHONPATH and set SHAPEBAG_TEST_HOLD_FIT=<path>: in every interpreter started
with that environment (the server and its spawned workers), fit_vocabulary touches <path>.entered and
then waits until <path> exists. Nothing in the package knows about it.
"""

from __future__ import annotations

import os

_BARRIER = os.environ.get("SHAPEBAG_TEST_HOLD_FIT")

if _BARRIER:
    import time
    from pathlib import Path

    import app.services.vocabularies as _vocabularies

    _real_fit = _vocabularies.fit_vocabulary

    def _held_fit(*args, **kwargs):
        Path(f"{_BARRIER}.entered").touch()
        while not Path(_BARRIER).exists():
            time.sleep(0.05)
        return _real_fit(*args, **kwargs)

    _vocabularies.fit_vocabulary = _held_fit
