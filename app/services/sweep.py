"""Remove the debris of writes cut short by a crash: temp files and temp directories under the data dir.

Every write goes temp -> fsync -> rename (storage/blobs.atomic_write, Vocabulary.save), so a process
killed mid-write leaves `.<name>.<random>.tmp` files or `.<id>.<random>` directories that nothing reads.
Only old ones are removed: a live writer in another process never takes `min_age_s` to finish.
"""

from __future__ import annotations

import logging
import os
import re
import shutil
import time
from pathlib import Path

from app.storage.blobs import writer_tag

log = logging.getLogger(__name__)

TEMP_FILE = re.compile(r"^\..+\.tmp$")  # atomic_write: .<name>.<pid>@<host>.<random>.tmp
WRITER = re.compile(r"\.(\d+)@([^./]+)\.[A-Za-z0-9_]+\.tmp$")  # who wrote it (older files: no tag)
TEMP_DIR = re.compile(r"^\.\d+\.[A-Za-z0-9_]+$")  # Vocabulary.save: .<id>.<random> (mkdtemp)
AREAS = ("meshes", "descriptions", "thumbnails", "vocabularies")


def _writer_gone(name: str) -> bool:
    """The temp file names a writer on this host whose process no longer exists."""
    m = WRITER.search(name)
    if m is None or m.group(2) != writer_tag().split("@", 1)[1]:
        return False  # untagged, or written from another host/container: only age can tell
    try:
        os.kill(int(m.group(1)), 0)
    except ProcessLookupError:
        return True
    except (PermissionError, OverflowError):
        return False
    return False


def sweep_temp_files(data_dir: Path, min_age_s: float = 3600.0) -> int:
    """Delete temp files/dirs older than `min_age_s` in the data dir's areas, and temp files of any age
    whose writer was a process of this host that is gone (a kill mid-write); returns how many."""
    cutoff = time.time() - min_age_s
    removed = 0
    for area in AREAS:
        root = Path(data_dir) / area
        if not root.is_dir():
            continue
        for path in list(root.rglob(".*")):
            try:
                if path.stat().st_mtime > cutoff and not _writer_gone(path.name):
                    continue
                if path.is_file() and TEMP_FILE.match(path.name):
                    path.unlink()
                elif path.is_dir() and TEMP_DIR.match(path.name):
                    shutil.rmtree(path)
                else:
                    continue
            except OSError:  # gone meanwhile, or not ours to remove: leave it
                continue
            removed += 1
    if removed:
        log.warning("removed %d temporary files left by interrupted writes under %s", removed, data_dir)
    return removed
