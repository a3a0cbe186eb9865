"""Work on uploaded bytes off the API process: describe a query, check an upload, render a preview.

Each of `processes` slots is a one-process executor serving one request at a time, so:
- a costly request holds one slot, never the others (before, one process served every search);
- a request that outruns the time limit gets its own process killed and replaced; requests in other
  slots never notice (before, restarting the shared pool failed every innocent request in flight);
- admission control: when every slot is busy, at most `queue` requests wait; the next one is refused
  at once (PoolBusyError: 503 + Retry-After) rather than piling up behind them;
- each process dies with the server and runs under RLIMIT_AS (`memory_mb`): a decode that explodes
  raises MemoryError there (413 here) instead of growing the API process.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import multiprocessing as mp
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from app.core.pipeline import DescribeParams, ShapeDescription, describe
from app.services.errors import (
    DescribeCrashedError,
    DescribeTimeoutError,
    PoolBusyError,
    ResourceLimitError,
)
from app.services.mesh_policy import check_bytes, load_upload
from app.worker.lifeline import cap_memory, die_with_parent
from app.worker.processes import pin_threads

log = logging.getLogger(__name__)


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


class QueryDescriber:
    def __init__(
        self,
        processes: int,
        params: DescribeParams,
        max_vertices: int,
        timeout_s: float,
        memory_mb: int = 0,
        queue: int = 8,
    ) -> None:
        self.processes = processes
        self.params = params
        self.max_vertices = max_vertices
        self.timeout_s = timeout_s
        self.memory_mb = memory_mb
        self.queue = queue
        self._slots = [self._new_executor() for _ in range(processes)]
        # admission state, touched only from the event loop's thread
        self._idle = list(range(processes))
        self._waiters: collections.deque[asyncio.Future[int]] = collections.deque()

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
        """Parse and validate an upload in the pool, under the same time limit; returns its vertex count."""
        return await self.run(check_bytes, (data, file_type, self.max_vertices), "reading the mesh")

    async def run(
        self, fn: Callable[..., Any], args: tuple, what: str, timeout_s: float | None = None
    ) -> Any:
        """fn(*args) in a slot of its own, under the time limit; the slot is freed whatever happens."""
        slot = await self._acquire(what)
        try:
            return await self._call(slot, fn, args, what, self.timeout_s if timeout_s is None else timeout_s)
        finally:
            self._release(slot)

    async def _call(self, slot: int, fn: Callable[..., Any], args: tuple, what: str, timeout_s: float) -> Any:
        loop = asyncio.get_running_loop()
        try:
            future = loop.run_in_executor(self._slots[slot], fn, *args)  # raises if already broken
            return await asyncio.wait_for(future, timeout_s)
        except TimeoutError:
            self._restart(slot)  # only this request's process: the others keep working
            raise DescribeTimeoutError(
                f"{what} took longer than {timeout_s:g} s; send a smaller mesh"
            ) from None
        except BrokenProcessPool:
            self._restart(slot)
            raise DescribeCrashedError(
                f"the process {what} stopped abruptly; it was restarted, retry"
            ) from None
        except MemoryError:  # raised in the pool process by RLIMIT_AS, pickled back here
            raise ResourceLimitError(
                f"{what} needs more than the memory limit of {self.memory_mb} MB; send a smaller mesh"
            ) from None

    async def _acquire(self, what: str) -> int:
        if self._idle:
            return self._idle.pop()
        if len(self._waiters) >= self.queue:
            raise PoolBusyError(
                f"all {self.processes} processes are busy and {self.queue} requests wait; retry shortly"
            )
        waiter: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        self._waiters.append(waiter)
        try:
            return await waiter
        except asyncio.CancelledError:  # the client went away while waiting
            if waiter.done() and not waiter.cancelled():
                self._release(waiter.result())  # handed a slot just as we were cancelled: pass it on
            else:
                self._waiters.remove(waiter)
            raise

    def _release(self, slot: int) -> None:
        while self._waiters:
            waiter = self._waiters.popleft()
            if not waiter.done():
                waiter.set_result(slot)
                return
        self._idle.append(slot)

    def _restart(self, slot: int) -> None:
        old, self._slots[slot] = self._slots[slot], self._new_executor()
        for proc in list(getattr(old, "_processes", {}).values()):  # no public API to kill a busy worker
            proc.terminate()
        old.shutdown(wait=False, cancel_futures=True)

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
