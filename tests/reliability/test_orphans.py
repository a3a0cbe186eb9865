"""Children die with their parent (issue 12, item 12): after `kill -9` of the server alone, its worker
processes, query pool processes and multiprocessing's resource tracker all exit within a bounded time,
instead of running on as orphans that keep taking jobs beside a restarted server's own."""

from __future__ import annotations

import contextlib
import os
import signal
import time
from pathlib import Path

import pytest

from tests.reliability.helpers import Proc, descendants, env_for, start_server

pytestmark = pytest.mark.slow
DEADLINE_S = 30.0  # the watcher polls each second; PDEATHSIG is immediate


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rfind(")") + 2] != "Z"


def _wait_for_children(pid: int, at_least: int) -> set[int]:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        kids = descendants(pid)
        if len(kids) >= at_least:
            return kids
        time.sleep(0.2)
    raise AssertionError(f"only {len(descendants(pid))} children appeared, expected {at_least}")


def _kill_parent_only_and_wait(proc: Proc, children: set[int]) -> list[int]:
    os.kill(proc.pid, signal.SIGKILL)  # the parent alone, not its process group
    proc.popen.wait(10)
    deadline = time.monotonic() + DEADLINE_S
    left = [c for c in children if _alive(c)]
    while left and time.monotonic() < deadline:
        time.sleep(0.2)
        left = [c for c in left if _alive(c)]
    return left


def test_server_killed_alone_takes_workers_pool_and_tracker_with_it(data_dir, tmp_path):
    server, base = start_server(
        data_dir,
        tmp_path / "s.log",
        SHAPEBAG_WORKERS="2",
        SHAPEBAG_SEARCH_PROCESSES="2",
        SHAPEBAG_WARM_UP="true",
    )
    try:
        children = _wait_for_children(server.pid, at_least=5)  # 2 workers, 2 pool processes, 1 tracker
        left = _kill_parent_only_and_wait(server, children)
        assert not left, f"still running {DEADLINE_S:g} s after the server died: {left}\n{server.log()}"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(server.pid, signal.SIGKILL)  # whatever is left in the group, if the test failed


def test_standalone_worker_processes_die_with_their_manager(data_dir, tmp_path):
    proc = Proc(["worker", "--processes", "2"], env_for(data_dir), tmp_path / "w.log")
    try:
        children = _wait_for_children(proc.pid, at_least=2)
        left = _kill_parent_only_and_wait(proc, children)
        assert not left, f"still running {DEADLINE_S:g} s after `shapebag worker` died: {left}\n{proc.log()}"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
