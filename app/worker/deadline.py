"""A wall-clock limit for one job: a clean stop when possible, the process's end when not.

- soft, at the limit: SIGALRM raises JobTimeout in the main thread. The eigen-solve and the resampling
  return to Python often (ARPACK's reverse communication calls back for every product), so this ends
  nearly every overrun within a moment, and the worker records the failure and takes the next job.
  JobTimeout is a BaseException, like KeyboardInterrupt: a solver's `except Exception` fallback must
  not swallow it and carry on.
- hard, `grace_s` later (only where a supervisor replaces the process: WorkerPool): one C call that
  never returns (a huge decimation) cannot be interrupted, so a watchdog thread records the failure
  (`on_hard`) and ends the process; its WorkerPool starts a new one.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
from collections.abc import Callable, Iterator

log = logging.getLogger(__name__)

HARD_EXIT_CODE = 70  # EX_SOFTWARE: the supervisor's log says why the worker went


class JobTimeout(BaseException):  # noqa: N818 - an interruption, like KeyboardInterrupt
    """The job ran past its wall-clock limit."""


@contextlib.contextmanager
def wall_clock_limit(
    seconds: float, on_hard: Callable[[], None] | None = None, grace_s: float = 15.0
) -> Iterator[None]:
    """Run the block under a limit of `seconds` (see the module docstring). on_hard None: no hard stop."""
    soft = threading.current_thread() is threading.main_thread()
    previous = None
    running = threading.Event()
    running.set()
    if soft:

        def interrupt(signum, frame) -> None:
            if running.is_set():  # not once the block has ended, just as the timer fired
                raise JobTimeout(f"past the limit of {seconds:g} s")

        previous = signal.signal(signal.SIGALRM, interrupt)
        signal.setitimer(signal.ITIMER_REAL, seconds)
    done = threading.Event()
    watchdog = None
    if on_hard is not None:

        def watch() -> None:
            if done.wait(seconds + grace_s):
                return
            log.error(
                "job still running %g s past its limit: recording its failure, ending the process", grace_s
            )
            try:
                on_hard()
            finally:
                os._exit(HARD_EXIT_CODE)

        watchdog = threading.Thread(target=watch, name="job-deadline", daemon=True)
        watchdog.start()
    try:
        yield
    finally:
        running.clear()
        done.set()
        if soft:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
        if watchdog is not None:
            watchdog.join()
