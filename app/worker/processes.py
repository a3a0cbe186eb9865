"""Worker processes (spawn context), each with BLAS pinned to one thread: N processes, N cores."""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import signal
import socket
import time
from multiprocessing.process import BaseProcess

from app.config import Settings
from app.worker.lifeline import cap_memory, die_with_parent, parent_alive

log = logging.getLogger(__name__)

RESPAWN_BACKOFF_S = 5.0  # a worker that keeps dying is restarted at most this often
THREAD_VARS = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)


def pin_threads() -> None:
    """One BLAS/OpenMP thread per process (set before numpy is imported in a fresh process)."""
    for var in THREAD_VARS:
        os.environ[var] = "1"
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        pass


class StopFlag:
    """Shutdown flag shared with worker processes: one raw shared byte, polled (Event-like API).

    Not multiprocessing.Event: its set() waits until every process sleeping in wait() has woken, and a
    worker killed while waiting never wakes, so shutdown hung forever once any worker had died.
    """

    POLL_S = 0.05

    def __init__(self, context) -> None:
        self._flag = context.RawValue("b", 0)

    def set(self) -> None:
        self._flag.value = 1

    def is_set(self) -> bool:
        return bool(self._flag.value)

    def wait(self, timeout: float | None = None) -> bool:
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self.is_set():
            left = self.POLL_S if deadline is None else deadline - time.monotonic()
            if left <= 0:
                return False
            time.sleep(min(self.POLL_S, left))
        return True


class ParentWatch:
    """The worker loop's stop condition: the shared flag, or a parent that is gone."""

    def __init__(self, stop: StopFlag, parent_pid: int) -> None:
        self.stop = stop
        self.parent_pid = parent_pid

    def is_set(self) -> bool:
        return self.stop.is_set() or not parent_alive(self.parent_pid)

    def wait(self, timeout: float | None = None) -> bool:
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self.is_set():
            left = StopFlag.POLL_S if deadline is None else deadline - time.monotonic()
            if left <= 0:
                return False
            time.sleep(min(StopFlag.POLL_S, left))
        return True


def worker_main(settings_json: str, name: str, stop: StopFlag, parent_pid: int) -> None:
    """Entry point of one spawned worker process."""
    die_with_parent(parent_pid)  # a SIGKILLed server must not leave its workers taking jobs
    pin_threads()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent owns shutdown; Ctrl-C reaches the group
    settings = Settings.model_validate_json(settings_json)
    cap_memory(settings.worker_memory_mb)
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(asctime)s %(processName)s %(levelname)s %(message)s"
    )
    logging.getLogger("faiss").setLevel(logging.WARNING)  # its loader reports each missing SIMD build
    from app.services.context import open_context
    from app.worker.runner import Worker

    ctx = open_context(settings)
    os.nice(settings.worker_nice)  # ingestion yields the cores to searches and uploads
    Worker(ctx, name, hard_deadline=True).run_forever(ParentWatch(stop, parent_pid))  # type: ignore[arg-type]


def process_name(prefix: str, slot: int) -> str:
    """A worker name unique across machines and containers: in each container the parent is often
    pid 1, so prefix-pid-slot alone repeats (and heartbeats of two workers would share one row)."""
    return f"{prefix}@{socket.gethostname()}-{os.getpid()}-{slot}"


class WorkerPool:
    """The embedded ingestion workers owned by the server's lifespan (or by `shapebag worker`)."""

    def __init__(self, settings: Settings, count: int, prefix: str = "embedded") -> None:
        self.settings = settings
        self.count = count
        self.prefix = prefix
        self._mp = mp.get_context("spawn")
        self._stop = StopFlag(self._mp)
        self.processes: list[BaseProcess] = []
        self._started_at: dict[int, float] = {}

    def start(self) -> None:
        for i in range(self.count):
            self.processes.append(self._spawn(i))
        log.info("started %d worker processes", self.count)

    def _spawn(self, slot: int) -> BaseProcess:
        saved = {v: os.environ.get(v) for v in THREAD_VARS}
        os.environ.update({v: "1" for v in THREAD_VARS})  # inherited by the spawned interpreter
        try:
            name = process_name(self.prefix, slot)
            p = self._mp.Process(
                target=worker_main,
                args=(self.settings.model_dump_json(), name, self._stop, os.getpid()),
                name=name,
                daemon=True,
            )
            p.start()
            self._started_at[slot] = time.monotonic()
            return p
        finally:
            for var, value in saved.items():
                if value is None:
                    os.environ.pop(var, None)
                else:
                    os.environ[var] = value

    def replace_dead(self) -> int:
        """Start a new process for each one that died (its job comes back when its lease expires)."""
        if self._stop.is_set():
            return 0
        replaced = 0
        for i, p in enumerate(self.processes):
            if not p.is_alive() and time.monotonic() - self._started_at.get(i, 0.0) > RESPAWN_BACKOFF_S:
                log.warning("worker %s died (exit code %s): starting a new one", p.name, p.exitcode)
                p.join(0)
                self.processes[i] = self._spawn(i)
                replaced += 1
        return replaced

    def alive(self) -> int:
        return sum(p.is_alive() for p in self.processes)

    def stop(self, timeout_s: float = 10.0) -> None:
        """Ask workers to finish their current job, then terminate stragglers (their leases expire)."""
        self._stop.set()
        for p in self.processes:
            p.join(timeout_s)
            if p.is_alive():
                p.terminate()
                p.join(2)
        self.processes.clear()
