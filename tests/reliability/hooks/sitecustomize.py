"""Test-only: hold a function of a real server or worker at a barrier, so a kill lands mid-step for sure.

Put this directory on PYTHONPATH and set SHAPEBAG_TEST_HOLD=<module>:<function> and
SHAPEBAG_TEST_HOLD_FILE=<path>: in every interpreter started with that environment (the server and its
spawned workers), the function touches <path>.entered and then waits until <path> exists. Nothing in
the package knows about it.
"""

from __future__ import annotations

import os

_TARGET = os.environ.get("SHAPEBAG_TEST_HOLD")
_BARRIER = os.environ.get("SHAPEBAG_TEST_HOLD_FILE")

if _TARGET and _BARRIER:
    import importlib
    import time
    from pathlib import Path

    _module_name, _function = _TARGET.split(":")
    _module = importlib.import_module(_module_name)
    _real = getattr(_module, _function)

    def _held(*args, **kwargs):
        Path(f"{_BARRIER}.entered").touch()
        while not Path(_BARRIER).exists():
            time.sleep(0.05)
        return _real(*args, **kwargs)

    setattr(_module, _function, _held)
