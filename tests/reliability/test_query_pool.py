"""The query pool (issue 12, item 3): several processes, admission control (503 when every slot is busy
and the wait queue is full), a timed-out request restarts only its own process, and a memory cap.

Requests are held in their pool process by a file barrier (released by the test), not by sleeps."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from app.core.pipeline import DescribeParams
from app.services.errors import DescribeTimeoutError, PoolBusyError, ResourceLimitError
from app.services.query_pool import QueryDescriber
from tests.conftest import wait_for
from tests.reliability.pool_tasks import allocate, hold_until


@pytest.fixture
def pool():
    describer = QueryDescriber(2, DescribeParams(), 3000, timeout_s=120, memory_mb=1024, queue=1)
    describer.warm_up()
    yield describer
    describer.close()


def _hold(pool: QueryDescriber, tmp: Path, name: str, timeout_s: float | None = None):
    args = (str(tmp / f"{name}.release"), str(tmp / f"{name}.started"))
    return asyncio.ensure_future(pool.run(hold_until, args, f"holding {name}", timeout_s))


async def _started(tmp: Path, *names: str) -> None:
    await asyncio.to_thread(wait_for, lambda: all((tmp / f"{n}.started").exists() for n in names), 60)


def test_two_processes_serve_two_requests_and_the_queue_bounds_the_rest(pool, tmp_path):
    async def scenario():
        a, b = _hold(pool, tmp_path, "a"), _hold(pool, tmp_path, "b")
        await _started(tmp_path, "a", "b")  # both held at once: two processes, not one
        assert pool.busy() == 2
        waiting = _hold(pool, tmp_path, "c")  # queue=1: this one waits for a slot...
        await asyncio.sleep(0)
        with pytest.raises(PoolBusyError):  # ...and the next is refused at once
            await pool.run(hold_until, ("x", "y"), "one too many")
        (tmp_path / "a.release").touch()
        pid_a = await a
        await _started(tmp_path, "c")  # the waiter got a's slot
        for name in ("b", "c"):
            (tmp_path / f"{name}.release").touch()
        pid_b, pid_c = await b, await waiting
        assert pid_a != pid_b and pid_c in (pid_a, pid_b)
        assert pool.busy() == 0

    asyncio.run(scenario())


def test_a_timeout_restarts_only_its_own_process_and_spares_the_request_beside_it(pool, tmp_path):
    async def scenario():
        innocent = _hold(pool, tmp_path, "innocent")
        await _started(tmp_path, "innocent")
        with pytest.raises(DescribeTimeoutError):  # never released: only the time limit ends it
            await _hold(pool, tmp_path, "runaway", timeout_s=1.0)
        (tmp_path / "innocent.release").touch()
        assert await innocent > 0  # still answered by its own process
        # the restarted slot works again
        (tmp_path / "after.release").touch()
        assert await _hold(pool, tmp_path, "after") > 0

    asyncio.run(scenario())


def test_a_request_past_the_memory_cap_is_a_413_not_a_bigger_process(pool):
    async def scenario():
        with pytest.raises(ResourceLimitError, match="memory limit of 1024 MB"):
            await pool.run(allocate, (4096,), "reading the mesh")
        assert await pool.run(allocate, (16,), "a small one") == 16 * 1024 * 1024

    asyncio.run(scenario())
