"""Who is asking: the client a piece of costly work is done for, so budgets can be shared per client.

The API's ClientBudget middleware (app/api/limits.py) names the client of each request (a hash of its
token, else its address) in a context variable; the query pool and ingestion read it from there, so no
route has to pass it along. Work started outside a request (tests, the CLI) belongs to "local".
"""

from __future__ import annotations

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


def current_client() -> str:
    return _CLIENT.get()


def set_client(key: str) -> object:
    """Name the client of the running request; returns the token to reset_client with."""
    return _CLIENT.set(key)


def reset_client(token: object) -> None:
    _CLIENT.reset(token)  # type: ignore[arg-type]
