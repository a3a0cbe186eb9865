"""Child processes die with their parent: a server killed with SIGKILL must not leave workers and query
processes running on as orphans (they kept taking jobs beside the restarted server's own).

Two mechanisms, because each has a gap: PR_SET_PDEATHSIG (Linux) signals the child when the *thread*
that spawned it exits, and cannot be set before the fork; a watcher thread polling getppid() covers
other platforms, spawning threads that end, and a parent that died before prctl ran.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import resource
import signal
import sys
import threading
from collections.abc import Callable
from typing import Any

log = logging.getLogger(__name__)

PR_SET_PDEATHSIG = 1
POLL_S = 1.0


def parent_alive(parent_pid: int) -> bool:
    """Our parent is still the process that started us (after its death we are re-parented)."""
    return os.getppid() == parent_pid


def die_with_parent(parent_pid: int, pdeathsig: bool = True) -> None:
    """Call first thing in a child: SIGTERM when the parent dies (prctl) plus a getppid() watcher.

    pdeathsig=False for children that may be spawned from a short-lived thread (the kernel would
    signal them when that thread ends, with the parent alive): the watcher alone covers them.
    """
    if pdeathsig and sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        except (OSError, AttributeError):  # no libc symbol: the watcher below still works
            log.warning("prctl(PR_SET_PDEATHSIG) unavailable; relying on the parent-pid watcher")
    if not parent_alive(parent_pid):  # died between our fork and the prctl call
        os._exit(1)

    def watch() -> None:
        while parent_alive(parent_pid):
            threading.Event().wait(POLL_S)
        os.kill(os.getpid(), signal.SIGTERM)  # the same death as PDEATHSIG, if that one did not come

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def cap_memory(megabytes: int) -> None:
    """RLIMIT_AS for this process: an allocation past it raises MemoryError instead of taking the host."""
    if megabytes <= 0:
        return
    limit = megabytes * 1024 * 1024
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))


def run_niced(nice: int, fn: Callable[..., Any], *args: Any) -> Any:
    """fn(*args) at `nice` more CPU niceness, in a thread of its own; this process keeps its priority.

    Linux gives each thread its own nice value, and an unprivileged process may raise it but never
    lower it back: a pool process that serves both searches and renders runs the renders in a niced
    thread, so the next search it serves still runs at full priority. Elsewhere (or nice <= 0): as is.
    """
    if nice <= 0 or not sys.platform.startswith("linux"):
        return fn(*args)
    outcome: dict[str, Any] = {}

    def niced() -> None:
        with contextlib.suppress(OSError):  # not permitted here: run at the usual priority
            # relative to the priority this thread started with (the caller's), so a service that was
            # itself started under `nice` still runs its background work below its searches
            tid = threading.get_native_id()
            os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + nice))
        try:
            outcome["value"] = fn(*args)
        except BaseException as exc:  # re-raised in the caller's thread (MemoryError included)
            outcome["error"] = exc

    thread = threading.Thread(target=niced, name="niced-call")
    thread.start()
    thread.join()
    if "error" in outcome:
        raise outcome["error"]
    return outcome["value"]
