"""How many pieces one API process matches at once, and who waits for the next turn.

A piece's matching (app/services/partial.py: the coarse pass, the scoring, the fits) runs in the API
process, in the threads that serve requests, after its describe in the query pool, and
`GET /models/{id}/similar` of an open model runs it with no describe in front: without a bound of
its own, a few clients each keeping their 8 costly requests in flight would have dozens of matchings
sharing the API's cores and its interpreter lock, and every other request would wait behind them
(docs/reliability.md, "Budgets"). The same rules as the query pool's kinds: `concurrency` at once;
`queue` waiting beyond them (then 503 `busy` + Retry-After); no client more than half the queue (429);
a full queue makes room for a newcomer by telling the newest waiter of a client with at least 2 more
waiting busy; a wait no longer than `wait_s` (503); a freed place goes to the waiting client running
fewest, then to the one served longest ago.

Touched from request threads (a route's work runs in the threadpool), so it is guarded by a lock.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from app.services.clients import ClientOverBudget, client_share, current_client, displaced
from app.services.errors import PoolBusyError


@dataclass
class _Waiter:
    client: str
    order: int  # arrival, the last tie-break
    turn: bool = False  # handed a place by a release
    displaced: bool = False  # its place in the queue went to another client's request


class PieceBudget:
    """A bounded, per-client fair gate in front of piece matching (one per API process)."""

    def __init__(self, concurrency: int, queue: int, wait_s: float) -> None:
        if concurrency < 1:
            raise ValueError("concurrency must be at least 1")
        self.concurrency = concurrency
        self.queue = queue
        self.wait_s = wait_s
        self._lock = threading.Condition()
        self._waiting: list[_Waiter] = []
        self._running: dict[str, int] = {}  # client -> matchings running
        self._served: dict[str, int] = {}  # client -> the turn it was last given
        self._turns = itertools.count(1)

    @property
    def active(self) -> int:
        with self._lock:
            return sum(self._running.values())

    @property
    def waiting(self) -> int:
        with self._lock:
            return len(self._waiting)

    @contextmanager
    def hold(self, what: str = "matching a piece") -> Iterator[None]:
        """A place to do `what` for the current client (app.services.clients), held for the block.

        Raises PoolBusyError (503) when the queue is full or no place came within wait_s, and
        ClientOverBudget (429) when this client already holds half the queue."""
        client = current_client()
        self._enter(client, what)
        try:
            yield
        finally:
            self._leave(client)

    def _enter(self, client: str, what: str) -> None:
        with self._lock:
            if not self._waiting and self._free():
                self._start(client)
                return
            if len(self._waiting) >= self.queue and not self._displace(client):
                raise PoolBusyError(f"{len(self._waiting)} requests already wait for {what}; retry shortly")
            mine = sum(w.client == client for w in self._waiting)
            if mine >= client_share(self.queue):  # one client never fills the queue by itself
                raise ClientOverBudget(f"{mine} of your requests already wait for {what}; wait for them")
            me = _Waiter(client, next(self._turns))
            self._waiting.append(me)
            deadline = time.monotonic() + self.wait_s
            while not me.turn:
                if me.displaced:
                    raise PoolBusyError(f"{what}: your place in the queue went to another client's request;"
                                        " retry shortly")
                left = deadline - time.monotonic()
                if left <= 0:
                    self._waiting.remove(me)
                    self._forget(client)
                    raise PoolBusyError(f"{what}: no place was free within {self.wait_s:g} s; retry shortly")
                self._lock.wait(left)

    def _leave(self, client: str) -> None:
        with self._lock:
            self._running[client] -= 1
            if not self._running[client]:
                del self._running[client]
            self._forget(client)
            self._dispatch()

    def _displace(self, client: str) -> bool:
        """Room for `client` in a full queue (app.services.clients.displaced, the query pool's rule):
        the waiter it takes the place of is told busy."""
        j = displaced([w.client for w in self._waiting], client)
        if j is None:
            return False
        victim = self._waiting.pop(j)
        victim.displaced = True
        self._forget(victim.client)
        self._lock.notify_all()
        return True

    def _free(self) -> bool:
        return sum(self._running.values()) < self.concurrency

    def _start(self, client: str) -> None:
        self._running[client] = self._running.get(client, 0) + 1
        self._served[client] = next(self._turns)

    def _forget(self, client: str) -> None:
        if client not in self._running and not any(w.client == client for w in self._waiting):
            self._served.pop(client, None)

    def _dispatch(self) -> None:
        """Hand free places to waiters: the client running fewest, then the one served longest ago
        (a client never served first), then the oldest request."""
        while self._waiting and self._free():
            me = min(self._waiting, key=lambda w: (self._running.get(w.client, 0),
                                                    self._served.get(w.client, 0), w.order))
            self._waiting.remove(me)
            me.turn = True
            self._start(me.client)
        self._lock.notify_all()
