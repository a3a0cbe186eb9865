"""The bound per client: who a request is for, and how much costly work one client may have in flight.

A client is its token when it presents a valid one (the API or admin token), else its address: a
made-up token names no one, so it cannot buy a fresh budget. Behind a reverse proxy, set
SHAPEBAG_FORWARDED_ALLOW_IPS to the proxy's address (`shapebag serve` hands it to uvicorn) so the
address is the client's, not the proxy's.
"""

from __future__ import annotations

import hmac
import re

from app.api.limits import RETRY_AFTER_S, drain, send_error
from app.services.clients import ClientOverBudget, reset_client, set_client

# the requests that cost a pool process or an upload (describe, check, explain, render), or several index
# searches and a read of their candidates' vectors (similar, with the fusion re-rank)
COSTLY = {
    "POST": re.compile(r"^/(search|models|explain|web/preview\.png)/?$"),
    "GET": re.compile(r"^/models/[^/]+/(explain|similar|thumbnail\.png)/?$"),
}
DRAIN_BYTES = 1 << 20


def client_key(scope: dict, tokens: dict[str, str]) -> str:
    """'token:api' / 'token:admin' for a request carrying that valid token, else 'addr:<ip>'.

    tokens: {"api": SHAPEBAG_API_TOKEN, "admin": SHAPEBAG_ADMIN_TOKEN} (empty ones are ignored)."""
    headers = dict(scope.get("headers") or [])
    presented = [headers.get(b"x-api-token", b""), headers.get(b"x-admin-token", b"")]
    auth = headers.get(b"authorization", b"")
    if auth[:7].lower() == b"bearer ":
        presented.append(auth[7:].strip())
    for name, secret in tokens.items():
        if secret and any(p and hmac.compare_digest(p, secret.encode()) for p in presented):
            return f"token:{name}"
    client = scope.get("client")
    return f"addr:{client[0] if client else 'unknown'}"


def is_costly(scope: dict) -> bool:
    pattern = COSTLY.get(scope.get("method", ""))
    return bool(pattern and pattern.match(scope.get("path", "")))


def document_client_bound(schema: dict) -> dict:
    """The OpenAPI schema with the 429 this bound answers on every costly operation."""
    refusal = {
        "description": "Too many requests: this client's costly requests in flight, or its share of a"
        " queue, are used up; retry after Retry-After seconds",
        "headers": {"Retry-After": {"schema": {"type": "integer"}}},
        "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorResponse"}}},
    }
    for path, operations in schema.get("paths", {}).items():
        for method, operation in operations.items():
            if is_costly({"method": method.upper(), "path": path}):
                operation.setdefault("responses", {}).setdefault("429", refusal)
    return schema


class ClientBudget:
    """ASGI middleware: names each request's client (services/clients.py, read by the budgets and the
    ingest queue) and lets one client have at most `max_requests` costly requests in flight; the next
    is 429 + Retry-After before its body is read. A client over its share of a budget's queue
    (ClientOverBudget, raised in the query pool) gets the same answer."""

    def __init__(self, app, max_requests: int, tokens: dict[str, str], timeout_s: float = 30.0) -> None:
        self.app = app
        self.max_requests = max_requests
        self.tokens = tokens
        self.timeout_s = timeout_s  # for reading a refused body
        self.in_flight: dict[str, int] = {}

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        key = client_key(scope, self.tokens)
        token = set_client(key)
        costly = is_costly(scope)
        started = False

        async def tracking_send(message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            if costly and self.in_flight.get(key, 0) >= self.max_requests:
                drained = await drain(receive, self.timeout_s, DRAIN_BYTES)  # so the client sees the 429
                message = f"{self.max_requests} of your costly requests are in progress; wait for them"
                await self._refuse(send, message, close=not drained)
                return
            if costly:
                self.in_flight[key] = self.in_flight.get(key, 0) + 1
            try:
                await self.app(scope, receive, tracking_send)
            except ClientOverBudget as exc:
                if started:
                    raise
                await self._refuse(send, exc.message, close=False)
            finally:
                if costly:
                    self.in_flight[key] -= 1
                    if not self.in_flight[key]:
                        del self.in_flight[key]
        finally:
            reset_client(token)

    @staticmethod
    async def _refuse(send, message: str, close: bool) -> None:
        headers = {"Retry-After": str(RETRY_AFTER_S)}
        await send_error(send, 429, "too_many_requests", message, headers, close=close)
