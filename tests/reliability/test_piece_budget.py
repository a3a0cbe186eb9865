"""The API's bound on pieces matched at once (app/services/piece_budget.py): at most `concurrency`
holders, a bounded queue, half of it per client, a wait that ends, and a freed place handed to the
waiting client running fewest. Threads stand for request threads; each names its client as the
ClientBudget middleware does."""

from __future__ import annotations

import threading
import time

import pytest

from app.services.clients import ClientOverBudget, reset_client, set_client
from app.services.errors import PoolBusyError
from app.services.piece_budget import PieceBudget


class Holder(threading.Thread):
    """Holds a place for `client` until released; records when it got it, or what refused it."""

    def __init__(self, budget: PieceBudget, client: str, log: list[str] | None = None) -> None:
        super().__init__(daemon=True)
        self.budget, self.client, self.log = budget, client, log
        self.entered = threading.Event()
        self.release = threading.Event()
        self.error: Exception | None = None

    def run(self) -> None:
        token = set_client(self.client)
        try:
            with self.budget.hold():
                if self.log is not None:
                    self.log.append(self.client)
                self.entered.set()
                self.release.wait(10)
        except (PoolBusyError, ClientOverBudget) as exc:
            self.error = exc
            self.entered.set()
        finally:
            reset_client(token)


def _until(check, timeout: float = 5.0) -> None:
    end = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.005)


def test_at_most_concurrency_hold_a_place_and_the_next_gets_it_when_one_leaves() -> None:
    budget = PieceBudget(concurrency=2, queue=4, wait_s=10)
    a, b, c = (Holder(budget, f"addr:{n}") for n in "abc")
    a.start(), b.start()
    assert a.entered.wait(5) and b.entered.wait(5)
    c.start()
    _until(lambda: budget.waiting == 1)
    assert not c.entered.is_set() and budget.active == 2
    a.release.set()
    assert c.entered.wait(5) and c.error is None
    assert budget.active == 2 and budget.waiting == 0
    b.release.set(), c.release.set()
    for h in (a, b, c):
        h.join(5)
    assert budget.active == 0


def test_a_full_queue_is_busy_at_once() -> None:
    budget = PieceBudget(concurrency=1, queue=1, wait_s=10)
    first, waiting = Holder(budget, "addr:a"), Holder(budget, "addr:b")
    first.start()
    assert first.entered.wait(5)
    waiting.start()
    _until(lambda: budget.waiting == 1)
    t = time.monotonic()
    refused = Holder(budget, "addr:c")
    refused.run()  # in this thread: refused without waiting
    assert isinstance(refused.error, PoolBusyError) and time.monotonic() - t < 1.0
    first.release.set()
    assert waiting.entered.wait(5) and waiting.error is None
    waiting.release.set()


def test_one_client_never_holds_more_than_half_the_queue() -> None:
    budget = PieceBudget(concurrency=1, queue=4, wait_s=10)
    first = Holder(budget, "addr:hog")
    first.start()
    assert first.entered.wait(5)
    queued = [Holder(budget, "addr:hog") for _ in range(2)]
    for h in queued:
        h.start()
    _until(lambda: budget.waiting == 2)
    third = Holder(budget, "addr:hog")
    third.run()
    assert isinstance(third.error, ClientOverBudget)
    other = Holder(budget, "addr:other")  # another client still finds room in the queue
    other.start()
    _until(lambda: budget.waiting == 3)
    assert other.error is None
    for h in (first, *queued, other):
        h.release.set()
    for h in (first, *queued, other):
        h.join(5)
    assert budget.active == 0 and budget.waiting == 0


def test_a_wait_ends_at_its_deadline_and_leaves_the_queue() -> None:
    budget = PieceBudget(concurrency=1, queue=4, wait_s=0.2)
    first = Holder(budget, "addr:a")
    first.start()
    assert first.entered.wait(5)
    t = time.monotonic()
    late = Holder(budget, "addr:b")
    late.run()
    waited = time.monotonic() - t
    assert isinstance(late.error, PoolBusyError) and 0.15 <= waited < 2.0
    assert budget.waiting == 0
    first.release.set()
    first.join(5)
    again = Holder(budget, "addr:b")  # the place is free again: no stale waiter takes it
    again.start()
    assert again.entered.wait(5) and again.error is None
    again.release.set()


def test_a_freed_place_goes_to_the_client_running_fewest() -> None:
    """The hog has one running and two waiting; a newcomer that arrives after them goes first."""
    budget = PieceBudget(concurrency=2, queue=8, wait_s=10)
    log: list[str] = []
    hog_running = Holder(budget, "addr:hog", log)
    other_running = Holder(budget, "addr:x", log)
    hog_running.start(), other_running.start()
    assert hog_running.entered.wait(5) and other_running.entered.wait(5)
    hog_waiting = [Holder(budget, "addr:hog", log) for _ in range(2)]
    for h in hog_waiting:
        h.start()
    _until(lambda: budget.waiting == 2)
    newcomer = Holder(budget, "addr:new", log)
    newcomer.start()
    _until(lambda: budget.waiting == 3)
    other_running.release.set()  # one place frees: the newcomer runs none, the hog one
    assert newcomer.entered.wait(5)
    assert log[2] == "addr:new"
    for h in (hog_running, newcomer, *hog_waiting):
        h.release.set()
    for h in (hog_running, other_running, newcomer, *hog_waiting):
        h.join(5)
    assert log.count("addr:hog") == 3 and budget.active == 0


def test_a_place_is_given_back_when_the_matching_fails() -> None:
    budget = PieceBudget(concurrency=1, queue=0, wait_s=1)
    with pytest.raises(RuntimeError), budget.hold():
        raise RuntimeError("the matching broke")
    assert budget.active == 0
    with budget.hold():
        assert budget.active == 1


def test_clients_that_each_fill_their_half_cannot_lock_a_newcomer_out() -> None:
    """Two clients fill the queue (2 + 2 of 4): a third arriving with nothing waiting takes the place of
    the newest waiter of a client with 2 more waiting, which is told busy, and is served in its turn; a
    client already waiting as many as the others is not given a place that way."""
    budget = PieceBudget(concurrency=1, queue=4, wait_s=10)
    running = Holder(budget, "addr:x")
    running.start()
    assert running.entered.wait(5)
    hogs = [Holder(budget, "addr:hog") for _ in range(2)]
    others = [Holder(budget, "addr:y") for _ in range(2)]
    for i, h in enumerate((*hogs, *others), start=1):  # one at a time: the queue's order is known
        h.start()
        _until(lambda n=i: budget.waiting == n)
    newcomer = Holder(budget, "addr:new")
    newcomer.start()
    _until(lambda: any(h.error is not None for h in hogs))
    assert isinstance(hogs[1].error, PoolBusyError) and hogs[0].error is None  # the newest was displaced
    assert budget.waiting == 4 and "another client" in str(hogs[1].error)
    late = Holder(budget, "addr:y")  # y already waits 2, as many as anyone: no room made for it
    late.run()
    assert isinstance(late.error, ClientOverBudget | PoolBusyError) and budget.waiting == 4
    for h in (running, hogs[0], *others, newcomer):  # every waiter left is served in its turn
        h.release.set()
    for h in (running, newcomer, *hogs, *others):
        h.join(5)
    assert newcomer.entered.is_set() and newcomer.error is None
    assert budget.active == 0 and budget.waiting == 0
