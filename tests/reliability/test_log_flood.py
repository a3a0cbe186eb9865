"""A repeating error does not flood the log: asyncio's refused accept() (no file descriptor left) is
let through once per interval, without its traceback, saying how many were held back."""

from __future__ import annotations

import logging

from app.commands._common import OncePerInterval, setup_logging


def _record(msg: str, created: float, exc: bool = True) -> logging.LogRecord:
    record = logging.LogRecord("asyncio", logging.ERROR, __file__, 1, msg, None, None)
    if exc:
        try:
            raise OSError(24, "Too many open files")
        except OSError as err:
            record.exc_info = (type(err), err, err.__traceback__)
    record.created = created
    return record


def test_one_line_per_interval_without_traceback_and_the_count_of_the_rest():
    flt = OncePerInterval("socket.accept() out of system resource", interval_s=10.0)
    msg = "socket.accept() out of system resource\nsocket: <fd=30>"
    first = _record(msg, 100.0)
    assert flt.filter(first) and first.exc_info is None  # the first passes, bare
    assert [flt.filter(_record(msg, 100.0 + t)) for t in (0.1, 1.0, 9.9)] == [False, False, False]
    later = _record(msg, 110.5)
    assert flt.filter(later) and "(3 more in the last 10 s, not logged)" in later.getMessage()
    other = _record("Task exception was never retrieved", 110.6)
    assert flt.filter(other) and other.exc_info is not None  # other errors untouched


def test_setup_logging_installs_the_filter_once():
    setup_logging()
    setup_logging(verbose=True)
    filters = [f for f in logging.getLogger("asyncio").filters if isinstance(f, OncePerInterval)]
    assert len(filters) == 1
