"""Budgets, not one queue (issue 34): each kind of costly work has its own concurrency, queue and
deadline in front of the shared processes; one process is kept for searches; one client cannot fill a
queue by itself and the next free process goes to the client served least; background kinds run niced.

Requests are held in their pool process by a file barrier (released by the test), not by sleeps."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path

import pytest

from app.core.pipeline import DescribeParams
from app.services.clients import ClientOverBudget, set_client
from app.services.errors import PoolBusyError
from app.services.query_pool import Budget, QueryDescriber
from tests.conftest import wait_for
from tests.reliability.pool_tasks import hold_until, niceness

BUDGETS = {
    "describe": Budget(2, 8),
    "check": Budget(1, 4),
    "explain": Budget(1, 2, nice=10),
    "render": Budget(1, 2, nice=10),
}


@pytest.fixture(scope="module")
def pool():
    p = QueryDescriber(3, DescribeParams(), 3000, timeout_s=120, memory_mb=1024, budgets=BUDGETS, reserve=1)
    p.warm_up()
    yield p
    p.close()


class Held:
    """One held request: started in its process, released by the test."""

    def __init__(
        self,
        pool: QueryDescriber,
        tmp: Path,
        name: str,
        kind: str,
        client: str = "a",
        timeout_s: float | None = None,
    ) -> None:
        self.tmp, self.name = tmp, name
        args = (str(tmp / f"{name}.release"), str(tmp / f"{name}.started"))

        async def call() -> int:
            set_client(client)  # this task's own context
            return await pool.run(hold_until, args, f"holding {name}", timeout_s, kind=kind)

        self.task = asyncio.ensure_future(call())

    @property
    def started(self) -> bool:
        return (self.tmp / f"{self.name}.started").exists()

    async def wait_started(self) -> None:
        await asyncio.to_thread(wait_for, lambda: self.started, 60)

    async def release(self) -> int:
        (self.tmp / f"{self.name}.release").touch()
        return await self.task


def test_slow_background_work_never_takes_the_process_kept_for_searches(pool, tmp_path):
    async def scenario():
        explain = Held(pool, tmp_path, "explain", "explain")
        render = Held(pool, tmp_path, "render", "render")
        check = Held(pool, tmp_path, "check", "check")
        await explain.wait_started()
        await render.wait_started()
        await asyncio.sleep(0.3)
        assert not check.started and pool.waiting("check") == 1  # the last process is kept...
        search = Held(pool, tmp_path, "search", "describe")
        await search.wait_started()  # ...for a search, which starts at once
        await search.release()
        await asyncio.sleep(0.3)
        assert not check.started  # free again, and kept again
        await explain.release()
        await check.wait_started()  # a second process free: the check may take one
        for held in (render, check):
            assert await held.release() > 0
        assert pool.busy() == 0

    asyncio.run(scenario())


def test_each_kind_has_its_own_concurrency_and_queue(pool, tmp_path):
    async def scenario():
        first = Held(pool, tmp_path, "r1", "render", client="a")
        await first.wait_started()
        waiting = Held(pool, tmp_path, "r2", "render", client="b")
        queued = Held(pool, tmp_path, "r3", "render", client="c")
        await asyncio.sleep(0.3)
        assert pool.active("render") == 1 and pool.waiting("render") == 2  # concurrency 1, queue 2
        set_client("d")
        with pytest.raises(PoolBusyError):  # the render queue is full...
            await pool.run(hold_until, ("x", "y"), "one render too many", kind="render")
        check = Held(pool, tmp_path, "check", "check")  # ...while another kind is let straight in
        await check.wait_started()
        assert await check.release() > 0
        for held in (first, waiting, queued):
            assert await held.release() > 0

    asyncio.run(scenario())


def test_one_client_fills_at_most_half_a_queue_and_the_least_served_client_goes_first(pool, tmp_path):
    async def scenario():
        running = Held(pool, tmp_path, "a0", "check", client="flooder")
        await running.wait_started()
        queued = [Held(pool, tmp_path, f"a{i}", "check", client="flooder") for i in (1, 2)]
        await asyncio.sleep(0.3)
        set_client("flooder")
        with pytest.raises(ClientOverBudget):  # check queue 4: two of them are all one client may hold
            await pool.run(hold_until, ("x", "y"), "a third waiting check", kind="check")
        normal = Held(pool, tmp_path, "b", "check", client="normal")  # arrives last, behind two
        await asyncio.sleep(0.3)
        assert pool.waiting("check") == 3
        await running.release()
        await normal.wait_started()  # the freed process goes to the client running none
        assert not any(h.started for h in queued)
        await normal.release()
        for held in queued:
            assert await held.release() > 0

    asyncio.run(scenario())


def test_a_full_queue_makes_room_for_a_client_with_nothing_waiting(pool, tmp_path):
    """Two clients fill the check queue (2 + 2 of 4): a third client's request takes the place of the
    newest waiter of a client with 2 more waiting (503 busy), waits, and is served in its turn."""
    async def scenario():
        running = Held(pool, tmp_path, "r", "check", client="x")
        await running.wait_started()
        hogs = [Held(pool, tmp_path, f"h{i}", "check", client="hog") for i in (0, 1)]
        await asyncio.sleep(0.2)
        others = [Held(pool, tmp_path, f"o{i}", "check", client="other") for i in (0, 1)]
        await asyncio.sleep(0.3)
        assert pool.waiting("check") == 4
        newcomer = Held(pool, tmp_path, "n", "check", client="newcomer")
        with pytest.raises(PoolBusyError, match="another client"):
            await hogs[1].task  # the hog's newest
        assert pool.waiting("check") == 4 and not hogs[0].task.done()
        left = (running, hogs[0], *others, newcomer)
        results = await asyncio.gather(*(held.release() for held in left))  # each served in its turn
        assert all(r > 0 for r in results)

    asyncio.run(scenario())


def test_the_deadline_counts_the_wait_and_frees_the_queue_place(pool, tmp_path):
    async def scenario():
        holder = Held(pool, tmp_path, "holder", "explain")
        await holder.wait_started()
        late = Held(pool, tmp_path, "late", "explain", client="b", timeout_s=1.0)
        with pytest.raises(PoolBusyError, match="no process was free within 1 s"):
            await late.task
        assert pool.waiting("explain") == 0 and not late.started
        assert await holder.release() > 0

    asyncio.run(scenario())


def test_a_niced_call_adds_to_the_priority_its_caller_runs_at():
    """run_niced raises the niceness by `nice`, not to it: a server started under `nice 5` still runs its
    background work 3 steps below its searches, and the caller's thread keeps its own priority."""
    import threading

    from app.worker.lifeline import run_niced

    seen: dict[str, int] = {}

    def caller() -> None:  # a thread of its own, so the test process keeps its priority
        tid = threading.get_native_id()
        base = os.getpriority(os.PRIO_PROCESS, tid)
        os.setpriority(os.PRIO_PROCESS, tid, min(19, base + 5))
        seen["caller"] = os.getpriority(os.PRIO_PROCESS, tid)
        seen["niced"] = run_niced(3, niceness)
        seen["plain"] = run_niced(0, niceness)
        seen["after"] = os.getpriority(os.PRIO_PROCESS, tid)

    thread = threading.Thread(target=caller)
    thread.start()
    thread.join()
    assert seen["niced"] == min(19, seen["caller"] + 3)
    assert seen["plain"] == seen["caller"] == seen["after"]


def test_background_kinds_run_niced_and_leave_the_process_at_its_priority(pool):
    async def scenario():
        base = os.getpriority(os.PRIO_PROCESS, 0)
        niced = [await pool.run(niceness, (), "render", kind="render") for _ in range(2)]
        plain = [await pool.run(niceness, (), "search", kind="describe") for _ in range(3)]
        return base, niced, plain

    base, niced, plain = asyncio.run(scenario())
    assert niced == [min(19, base + 10)] * 2
    assert plain == [base] * 3  # the same processes served the renders: they kept their own priority


def test_the_displacement_rule_on_hand_made_queues():
    """app.services.clients.displaced, the rule both the query pool and the piece budget admit by: the
    newest waiter of the client with most waiting, when it has at least 2 more than the newcomer."""
    from app.services.clients import client_share, displaced

    assert displaced([], "new") is None
    assert displaced(["a", "b", "a", "b"], "new") == 2  # a and b tie at 2: a, counted first, gives its newest
    assert displaced(["a", "b", "b", "a", "b"], "new") == 4  # b has most
    assert displaced(["a", "b", "a", "b"], "a") is None  # a already waits 2: no room made for a third
    assert displaced(["a", "b", "c", "d"], "new") is None  # one each: full to all
    assert displaced(["a", "a", "a", "n"], "n") == 2  # 3 against 1: still 2 more
    assert [client_share(q) for q in (0, 1, 2, 8, 9)] == [1, 1, 1, 4, 4]
