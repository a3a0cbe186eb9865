"""Costly work on meshes, off the API process: describe a query, check an upload, explain, render.

A few processes (`processes`) are shared by every kind of work, and each kind has its own budget in
front of them (docs/reliability.md, "Budgets"):
- at most `concurrency` requests of a kind run at once, at most `queue` wait; the next is refused at
  once (PoolBusyError: 503 + Retry-After) rather than piling up behind them;
- `reserve` processes are kept for query descriptions: the other kinds together never take the last
  one, so an explain or a render, however slow, never makes a search wait for a process;
- a deadline per request (`timeout_s`, waiting included): a process that overruns is killed and
  replaced (504), requests in other processes never notice; a request still waiting for a process at
  its deadline is refused as busy (503), since that says nothing about the request;
- per client (services/clients.py): a client waits for at most half of a kind's queue
  (ClientOverBudget: 429), and a freed process goes to the waiting client that runs the fewest of
  that kind, so one client's burst delays only itself;
- background kinds run at a lower CPU priority (`nice`, per call), so they yield the cores to
  searches;
- each process dies with the server and runs under RLIMIT_AS (`memory_mb`): a decode that explodes
  raises MemoryError there (413 here) instead of growing the API process.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing as mp
import os
import time
from collections.abc import Awaitable, Callable, Hashable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any

from app.config import Settings
from app.core.pipeline import DescribeParams, ShapeDescription, describe
from app.services.clients import ClientOverBudget, client_share, current_client, displaced
from app.services.errors import (
    DescribeCrashedError,
    DescribeTimeoutError,
    PoolBusyError,
    ResourceLimitError,
)
from app.services.mesh_policy import check_bytes, load_upload
from app.worker.lifeline import cap_memory, die_with_parent, run_niced
from app.worker.processes import pin_threads

log = logging.getLogger(__name__)

KINDS = ("describe", "check", "explain", "render")  # also the order a freed process is offered in


@dataclass(frozen=True)
class Budget:
    """What one kind of work may hold. timeout_s None: the pool's own (describe_timeout_s)."""

    concurrency: int
    queue: int
    timeout_s: float | None = None
    nice: int = 0  # added CPU niceness while running (0: as the API)


def describe_bytes(
    data: bytes, file_type: str, params: DescribeParams, max_vertices: int
) -> tuple[ShapeDescription, dict[str, float]]:
    """Runs in a pool process: bytes -> description and seconds per stage (load + describe stages)."""
    t = time.perf_counter()
    mesh = load_upload(data, file_type, max_vertices)
    seconds = {"load": time.perf_counter() - t}
    description = describe(mesh, params)
    seconds.update(description.seconds)
    return description, seconds


def init_process(parent_pid: int, memory_mb: int) -> None:
    """Initializer of each pool process: die with the server, one BLAS thread, capped memory."""
    # no PDEATHSIG: a slot's process starts on first use, from whichever thread submits (under
    # TestClient a per-request thread), and PDEATHSIG would fire when that thread ends
    die_with_parent(parent_pid, pdeathsig=False)
    pin_threads()
    cap_memory(memory_mb)


class _Waiter:
    __slots__ = ("client", "future")

    def __init__(self, client: str, future: asyncio.Future[int]) -> None:
        self.client = client
        self.future = future


class QueryDescriber:
    """The shared processes and the budgets in front of them (touched only from the event loop)."""

    def __init__(
        self,
        processes: int,
        params: DescribeParams,
        max_vertices: int,
        timeout_s: float,
        memory_mb: int = 0,
        queue: int = 8,
        budgets: dict[str, Budget] | None = None,
        reserve: int = 0,
    ) -> None:
        self.processes = processes
        self.params = params
        self.max_vertices = max_vertices
        self.timeout_s = timeout_s
        self.memory_mb = memory_mb
        given = budgets or {}
        self.budgets = {kind: given.get(kind, Budget(processes, queue)) for kind in KINDS}
        self.reserve = min(reserve, processes - 1)  # kept for "describe"; never all of them
        self._slots = [self._new_executor() for _ in range(processes)]
        self._idle = list(range(processes))
        self._waiters: dict[str, list[_Waiter]] = {kind: [] for kind in KINDS}
        self._running: dict[str, dict[str, int]] = {kind: {} for kind in KINDS}  # kind -> client -> n
        self._served: dict[str, dict[str, int]] = {kind: {} for kind in KINDS}  # kind -> client -> turn
        self._turn = 0
        self._shared: dict[Hashable, asyncio.Future[Any]] = {}

    def _new_executor(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(
            1,
            mp_context=mp.get_context("spawn"),
            initializer=init_process,
            initargs=(os.getpid(), self.memory_mb),
        )

    async def describe(self, data: bytes, file_type: str) -> tuple[ShapeDescription, dict[str, float]]:
        """Raises InvalidMeshError (from the pool process), DescribeTimeoutError, PoolBusyError..."""
        args = (data, file_type, self.params, self.max_vertices)
        return await self.run(describe_bytes, args, "describing the query mesh")

    async def check(self, data: bytes, file_type: str) -> int:
        """Parse and validate an upload in the pool, under the check budget; returns its vertex count."""
        args = (data, file_type, self.max_vertices)
        return await self.run(check_bytes, args, "reading the mesh", kind="check")

    async def run(
        self,
        fn: Callable[..., Any],
        args: tuple,
        what: str,
        timeout_s: float | None = None,
        kind: str = "describe",
    ) -> Any:
        """fn(*args) in a process of its own under `kind`'s budget; the deadline counts the wait too."""
        budget = self.budgets[kind]
        limit = timeout_s if timeout_s is not None else budget.timeout_s or self.timeout_s
        deadline = time.monotonic() + limit
        client = current_client()
        slot = await self._acquire(kind, client, what, limit)
        try:
            left = max(0.001, deadline - time.monotonic())
            return await self._call(slot, fn, args, what, left, limit, budget.nice)
        finally:
            self._release(slot, kind, client)

    async def _call(
        self, slot: int, fn: Callable[..., Any], args: tuple, what: str, left: float, limit: float, nice: int
    ) -> Any:
        loop = asyncio.get_running_loop()
        try:
            future = loop.run_in_executor(self._slots[slot], run_niced, nice, fn, *args)
            return await asyncio.wait_for(future, left)
        except TimeoutError:
            self._restart(slot)  # only this request's process: the others keep working
            raise DescribeTimeoutError(f"{what} took longer than {limit:g} s; send a smaller mesh") from None
        except BrokenProcessPool:
            self._restart(slot)
            raise DescribeCrashedError(
                f"the process {what} stopped abruptly; it was restarted, retry"
            ) from None
        except MemoryError:  # raised in the pool process by RLIMIT_AS, pickled back here
            raise ResourceLimitError(
                f"{what} needs more than the memory limit of {self.memory_mb} MB; send a smaller mesh"
            ) from None

    async def shared(self, key: Hashable, make: Callable[[], Awaitable[Any]]) -> Any:
        """Concurrent requests of one client for the same work (`key`) share one run of make(); a caller
        that goes away does not cancel it for the others. Per client, so that one client's refusal
        (over its share, 429) is never another's answer."""
        key = (current_client(), key)
        task = self._shared.get(key)
        if task is None:
            task = asyncio.ensure_future(make())
            self._shared[key] = task
            task.add_done_callback(lambda _: self._shared.pop(key, None))
        return await asyncio.shield(task)

    # ---- admission ---------------------------------------------------------------------------------

    def _may_start(self, kind: str) -> bool:
        if not self._idle or self.active(kind) >= self.budgets[kind].concurrency:
            return False
        kept = 0 if kind == "describe" else max(0, self.reserve - self.active("describe"))
        return len(self._idle) > kept

    async def _acquire(self, kind: str, client: str, what: str, limit: float) -> int:
        queue = self._waiters[kind]
        if not queue and self._may_start(kind):
            return self._start(kind, client)
        budget = self.budgets[kind]
        if len(queue) >= budget.queue and not self._displace(kind, client, what):
            raise PoolBusyError(f"{len(queue)} requests already wait for {what}; retry shortly")
        mine = sum(w.client == client for w in queue)
        if mine >= client_share(budget.queue):  # one client never fills a kind's queue by itself
            raise ClientOverBudget(f"{mine} of your requests already wait for {what}; wait for them")
        waiter = _Waiter(client, asyncio.get_running_loop().create_future())
        queue.append(waiter)
        try:
            return await asyncio.wait_for(asyncio.shield(waiter.future), limit)
        except TimeoutError:  # busy, not the request's fault: a 503 to retry, never kept as its failure
            self._abandon(kind, waiter)
            raise PoolBusyError(f"{what}: no process was free within {limit:g} s; retry shortly") from None
        except asyncio.CancelledError:  # the client went away while waiting
            self._abandon(kind, waiter)
            raise

    def _displace(self, kind: str, client: str, what: str) -> bool:
        """Room for `client` in a full queue (app.services.clients.displaced): the waiter it takes the
        place of is told busy (503)."""
        queue = self._waiters[kind]
        j = displaced([w.client for w in queue], client)
        if j is None:
            return False
        victim = queue.pop(j)
        victim.future.set_exception(
            PoolBusyError(f"{what}: your place in the queue went to another client's request; retry shortly"))
        if victim.client not in self._running[kind] and not any(w.client == victim.client for w in queue):
            self._served[kind].pop(victim.client, None)
        return True

    def _abandon(self, kind: str, waiter: _Waiter) -> None:
        if waiter.future.done() and not waiter.future.cancelled():
            self._release(waiter.future.result(), kind, waiter.client)  # handed a slot as we left
        else:
            waiter.future.cancel()
            self._waiters[kind].remove(waiter)
            gone = not any(w.client == waiter.client for w in self._waiters[kind])
            if gone and waiter.client not in self._running[kind]:
                self._served[kind].pop(waiter.client, None)

    def _start(self, kind: str, client: str) -> int:
        running = self._running[kind]
        running[client] = running.get(client, 0) + 1
        self._turn += 1
        self._served[kind][client] = self._turn
        return self._idle.pop()

    def _release(self, slot: int, kind: str, client: str) -> None:
        running = self._running[kind]
        running[client] -= 1
        if not running[client]:
            del running[client]
            if not any(w.client == client for w in self._waiters[kind]):
                self._served[kind].pop(client, None)  # nothing left here: forget it
        self._idle.append(slot)
        self._dispatch()

    def _dispatch(self) -> None:
        """Hand idle processes to waiters: kinds in KINDS order; in a kind, round-robin over clients
        (the client running fewest, then the one served longest ago; a new client first)."""
        for kind in KINDS:
            queue = self._waiters[kind]
            running, served = self._running[kind], self._served[kind]
            while queue and self._may_start(kind):
                waiter = min(queue, key=lambda w: (running.get(w.client, 0), served.get(w.client, 0)))
                queue.remove(waiter)
                waiter.future.set_result(self._start(kind, waiter.client))

    def _restart(self, slot: int) -> None:
        old, self._slots[slot] = self._slots[slot], self._new_executor()
        for proc in list(getattr(old, "_processes", {}).values()):  # no public API to kill a busy worker
            proc.terminate()
        old.shutdown(wait=False, cancel_futures=True)

    def active(self, kind: str) -> int:
        return sum(self._running[kind].values())

    def waiting(self, kind: str) -> int:
        return len(self._waiters[kind])

    def busy(self) -> int:
        return self.processes - len(self._idle)

    def warm_up(self) -> None:
        """Start every slot's process now rather than on the first query (best effort)."""
        try:
            for future in [executor.submit(int, 0) for executor in self._slots]:
                future.result()
        except Exception as exc:  # e.g. shut down meanwhile; the first query will start the process
            log.info("query pool warm-up skipped: %s", exc)

    def close(self) -> None:
        for executor in self._slots:
            executor.shutdown(wait=True, cancel_futures=True)


# background kinds yield the cores to query descriptions; an upload check is waited on, but less urgently
NICE = {"describe": 0, "check": 5, "explain": 10, "render": 10}


def from_settings(settings: Settings) -> QueryDescriber:
    """The server's pool: SHAPEBAG_POOL_PROCESSES processes, one kept for searches, four budgets."""
    processes = settings.pool_processes
    budgets = {
        "describe": Budget(min(settings.search_processes, processes), settings.search_queue),
        **{
            kind: Budget(min(b.concurrency, processes), b.queue, b.timeout_s, NICE[kind])
            for kind, b in (
                ("check", settings.check_budget),
                ("explain", settings.explain_budget),
                ("render", settings.render_budget),
            )
        },
    }
    return QueryDescriber(
        processes,
        settings.describe.params(),
        settings.max_vertices,
        settings.describe_timeout_s,
        settings.worker_memory_mb,
        settings.search_queue,
        budgets=budgets,
        reserve=1,
    )
