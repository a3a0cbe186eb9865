"""Who is asking: the client a piece of costly work is done for, so budgets can be shared per client.

The API's ClientBudget middleware (app/api/limits.py) names the client of each request (a hash of its
token, else its address) in a context variable; the query pool and ingestion read it from there, so no
route has to pass it along. Work started outside a request (tests, the CLI) belongs to "local".
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from contextvars import ContextVar

LOCAL = "local"
_CLIENT: ContextVar[str] = ContextVar("shapebag_client", default=LOCAL)


class ClientOverBudget(Exception):  # noqa: N818 - answered as 429, like a rate limit
    """One client asks for more than its share (429 + Retry-After).

    Deliberately not a ServiceError: the ClientBudget middleware, which owns the per-client bound,
    answers it, outside the routes' error handlers."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


def client_share(queue: int) -> int:
    """Waiters one client may have in a queue of `queue` places: half, so it never fills one alone."""
    return max(1, queue // 2)


def displaced(waiting: Sequence[str], client: str) -> int | None:
    """Which waiter a full queue tells busy to make room for `client`: the index into `waiting` (each
    waiter's client, oldest first) of the newest waiter of the client with most waiting, when that
    client has at least 2 more waiting than `client`; None: no room is made. So clients that each
    fill their share cannot lock a newcomer out; only a queue of many clients is full to all. The
    query pool's kinds and the piece budget admit by this one rule."""
    counts = Counter(waiting)
    if not counts:
        return None
    heaviest, most = counts.most_common(1)[0]
    if most < counts[client] + 2:
        return None
    return max(i for i, c in enumerate(waiting) if c == heaviest)


def current_client() -> str:
    return _CLIENT.get()


def set_client(key: str) -> object:
    """Name the client of the running request; returns the token to reset_client with."""
    return _CLIENT.set(key)


def reset_client(token: object) -> None:
    _CLIENT.reset(token)  # type: ignore[arg-type]
