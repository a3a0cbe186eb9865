"""A connection finishes its request's headers within a deadline, or is closed.

uvicorn arms no timer while a request's headers arrive: its keep-alive timer runs only between two
requests, and any byte cancels it. A client that opens connections and never finishes their headers
(slowloris) holds one file descriptor each for as long as it likes; 20,000 of them took the API
process to its descriptor limit, no request of anyone was answered for 10-20 s, and each refused
accept() wrote a traceback to the log (red team, 2026-12-05). This protocol, given to uvicorn by
`shapebag serve`, closes a connection whose next request's headers are not complete
HEADER_TIMEOUT_S after it opened or after its last response. A request whose headers are in is
never touched: its body has its own limits (app/api/limits.py: GuardUploads).

Behind the shipped nginx (deploy/nginx) the proxy's own `client_header_timeout` and per-address
connection cap come first; this guards a server reached directly.
"""

from __future__ import annotations

import asyncio
import os
from typing import Any

from uvicorn.protocols.http.h11_impl import H11Protocol

HEADER_TIMEOUT_S = 15.0  # the default of SHAPEBAG_HEADER_TIMEOUT_S (app/config.py)


class HeaderDeadlineProtocol(H11Protocol):
    """uvicorn's h11 protocol with a deadline on each request's headers."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # read here, not passed: uvicorn builds the protocol itself, in every API process it starts
        self.header_timeout_s = float(os.environ.get("SHAPEBAG_HEADER_TIMEOUT_S", HEADER_TIMEOUT_S))
        self._header_deadline: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm_header_deadline()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._arm_header_deadline()  # the next request on this connection gets the same deadline

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_header_deadline()
        super().connection_lost(exc)

    def _arm_header_deadline(self) -> None:
        self._cancel_header_deadline()
        if self.transport.is_closing():
            return
        # the cycle now (None, or the one just answered): a new one is made when headers complete
        self._header_deadline = self.loop.call_later(self.header_timeout_s, self._header_timeout, self.cycle)

    def _cancel_header_deadline(self) -> None:
        if self._header_deadline is not None:
            self._header_deadline.cancel()
            self._header_deadline = None

    def _header_timeout(self, cycle_then: object) -> None:
        self._header_deadline = None
        if self.cycle is cycle_then and not self.transport.is_closing():  # no new request's headers
            self.transport.close()
