"""Room on the data directory: a free-space floor and an optional quota, checked before a write.

A full filesystem makes SQLite fail mid-transaction ("database or disk is full") and every request that
touches the database answer 500, DELETE included, so an operator cannot free space through the API.
Refusing new writes while some room is left keeps reads and deletes working. The probes are module
functions so that tests can fake a full disk.
"""

from __future__ import annotations

import os
import shutil
import threading
import time
from pathlib import Path

from app.config import StorageSettings
from app.services.errors import InsufficientStorageError

MB = 1 << 20
_measured: dict[Path, tuple[float, int]] = {}  # data_dir -> (monotonic time, bytes)
_lock = threading.Lock()


def free_bytes(path: Path) -> int:
    """Bytes free for this user on the filesystem holding `path`."""
    return shutil.disk_usage(path).free


def tree_bytes(path: Path) -> int:
    """Bytes of every file under `path` (a walk: cached by stored_bytes)."""
    total = 0
    for root, _, files in os.walk(path):
        for name in files:
            try:
                total += os.lstat(os.path.join(root, name)).st_size
            except FileNotFoundError:  # removed while walking
                continue
    return total


def stored_bytes(data_dir: Path, max_age_s: float) -> int:
    """tree_bytes(data_dir), measured again at most every `max_age_s` seconds."""
    now = time.monotonic()
    with _lock:
        seen = _measured.get(data_dir)
        if seen is not None and now - seen[0] < max_age_s:
            return seen[1]
    total = tree_bytes(data_dir)
    with _lock:
        _measured[data_dir] = (now, total)
    return total


def check_room(data_dir: Path, limits: StorageSettings, incoming: int = 0) -> None:
    """Raise InsufficientStorageError when writing `incoming` more bytes would go under the free-space
    floor or past the quota."""
    free = free_bytes(data_dir)
    if free - incoming < limits.min_free_mb * MB:
        raise InsufficientStorageError(
            f"the server's disk is nearly full ({free // MB} MB free, {limits.min_free_mb} MB kept free):"
            " nothing new is stored until an operator frees space (DELETE /models/{id} still works)"
        )
    if limits.quota_mb:
        used = stored_bytes(data_dir, limits.measure_interval_s)
        if used + incoming > limits.quota_mb * MB:
            raise InsufficientStorageError(
                f"the storage quota of {limits.quota_mb} MB is used up ({used // MB} MB stored): nothing new"
                " is stored until models are deleted (DELETE /models/{id}) or the quota is raised"
            )
