"""Functions the query-pool tests run in pool processes (importable by spawned interpreters)."""

from __future__ import annotations

import os
import time
from pathlib import Path


def hold_until(release: str, started: str) -> int:
    """Mark `started`, then wait until the file `release` exists; returns this process's pid."""
    Path(started).touch()
    deadline = time.monotonic() + 120  # a forgotten test never leaves a process behind for long
    while not Path(release).exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    return os.getpid()


def allocate(megabytes: int) -> int:
    """Touch `megabytes` of memory (what a decode bomb does); returns the bytes held."""
    block = bytearray(megabytes * 1024 * 1024)
    return len(block)


def niceness() -> int:
    """The CPU niceness of the thread running this call (Linux: per thread)."""
    import threading

    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
