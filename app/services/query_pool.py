"""Describing query meshes off the event loop: a process pool owned by the lifespan, with a time limit."""

from __future__ import annotations

import asyncio
import logging
import multiprocessing as mp
import os
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

from app.core.pipeline import DescribeParams, ShapeDescription, describe
from app.services.errors import DescribeCrashedError, DescribeTimeoutError
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
    die_with_parent(parent_pid)
    pin_threads()
    cap_memory(memory_mb)


class QueryDescriber:
    def __init__(
        self, processes: int, params: DescribeParams, max_vertices: int, timeout_s: float, memory_mb: int = 0
    ) -> None:
        self.processes = processes
        self.memory_mb = memory_mb
        self.params = params
        self.max_vertices = max_vertices
        self.timeout_s = timeout_s
        self._pool = self._new_pool()

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(
            self.processes,
            mp_context=mp.get_context("spawn"),
            initializer=init_process,
            initargs=(os.getpid(), self.memory_mb),
        )

    async def describe(self, data: bytes, file_type: str) -> tuple[ShapeDescription, dict[str, float]]:
        """Raises InvalidMeshError (from the pool process) or DescribeTimeoutError."""
        args = (data, file_type, self.params, self.max_vertices)
        return await self._call(describe_bytes, args, "describing the query mesh")

    async def check(self, data: bytes, file_type: str) -> int:
        """Parse and validate an upload in the pool, under the same time limit; returns its vertex count."""
        return await self._call(check_bytes, (data, file_type, self.max_vertices), "reading the mesh")

    async def _call(self, fn, args: tuple, what: str):
        loop = asyncio.get_running_loop()
        pool = self._pool
        future = loop.run_in_executor(pool, fn, *args)
        try:
            return await asyncio.wait_for(future, self.timeout_s)
        except TimeoutError:
            self._restart(pool)  # a runaway solve must not hold a pool process forever
            raise DescribeTimeoutError(
                f"{what} took longer than {self.timeout_s:g} s; send a smaller mesh"
            ) from None
        except BrokenProcessPool:
            self._restart(pool)
            raise DescribeCrashedError(
                f"the process {what} stopped abruptly; it was restarted, retry"
            ) from None

    def _restart(self, pool: ProcessPoolExecutor) -> None:
        if pool is not self._pool:
            return
        self._pool = self._new_pool()
        for proc in list(getattr(pool, "_processes", {}).values()):  # no public API to kill a busy worker
            proc.terminate()
        pool.shutdown(wait=False, cancel_futures=True)

    def warm_up(self) -> None:
        """Start the pool processes now rather than on the first query (best effort)."""
        try:
            list(self._pool.map(int, range(self.processes)))
        except Exception as exc:  # e.g. shut down meanwhile; the first query will start the pool
            log.info("query pool warm-up skipped: %s", exc)

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
