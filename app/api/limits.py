"""Request limits the routes share: no compressed bodies, plain file names, printable text fields.

The byte limit itself is enforced while streaming (app/api/uploads.py); geometry is checked in the
query pool (QueryDescriber.check, app/services/mesh_policy.py). These checks are cheap and run first.
"""

from __future__ import annotations

import asyncio
import json
import os
import tempfile
import time
import unicodedata
from pathlib import Path
from typing import Annotated

from fastapi import Path as PathParam
from fastapi import Query

from app.api.uploads import UploadForm
from app.core.mesh import detect_format
from app.services.clients import current_client
from app.services.errors import InvalidInputError

RETRY_AFTER_S = 2  # a client over its share (the upload slots here, ClientBudget's requests): 429

MAX_FILENAME_CHARS = 255
MAX_TEXT_CHARS = 200  # name; label is held to 100 by ModelCreate on /models
TEXT_FIELDS = ("name", "label")
# Cc: control (NUL, ESC, BEL...), Cf: format (bidi overrides, zero-width), Cs: surrogates, Co: private use
REFUSED_CATEGORIES = {
    "Cc": "a control character",
    "Cf": "an invisible formatting character",
    "Cs": "a surrogate",
    "Co": "a private-use character",
}


def _odd_character(text: str) -> str | None:
    if "\ufffd" in text:  # what the form reader puts where the bytes were not UTF-8
        return "bytes that are not valid UTF-8"
    for ch in text:
        what = REFUSED_CATEGORIES.get(unicodedata.category(ch))
        if what is not None:
            return f"{what} (U+{ord(ch):04X})"
    return None


def check_text(name: str, value: str | None) -> None:
    """InvalidInputError (422) for a text field holding a control, invisible formatting, surrogate or
    private-use character (the rule of the form's name and label, for JSON bodies' text too)."""
    odd = None if value is None else _odd_character(value)
    if odd is not None:
        raise InvalidInputError(f"{name}: contains {odd}")


def check_filename(filename: str) -> str:
    """The upload's file name is only used for its extension and default display name: a plain name."""
    if len(filename) > MAX_FILENAME_CHARS:
        raise InvalidInputError(f"the file name is longer than {MAX_FILENAME_CHARS} characters")
    if "/" in filename or "\\" in filename or filename in (".", "..") or filename.startswith(".."):
        raise InvalidInputError("the file name must be a plain name, not a path (no '/', '\\' or '..')")
    odd = _odd_character(filename)
    if odd is not None:
        raise InvalidInputError(f"the file name contains {odd}")
    return filename


def upload_format(filename: str) -> str:
    """'chair.obj' -> 'obj'; UnsupportedFormatError (415 unsupported_format, as on /search) otherwise."""
    return detect_format(filename)


def check_form(form: UploadForm, file_field: str = "file") -> None:
    """Raise InvalidInputError (422) for a bad file name or an odd/overlong name or label."""
    if file_field in form.files:
        check_filename(form.files[file_field][0])
    for name in TEXT_FIELDS:
        value = form.fields.get(name)
        if value is None:
            continue
        if len(value) > MAX_TEXT_CHARS:
            raise InvalidInputError(f"{name}: longer than {MAX_TEXT_CHARS} characters")
        check_text(name, value)


async def send_error(
    send, status: int, code: str, message: str, headers: dict[str, str] | None = None, close: bool = True
) -> None:
    """A JSON error response sent straight from ASGI middleware (closing the connection unless told)."""
    body = json.dumps({"error": {"code": code, "message": message}}).encode()
    raw = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    raw += [(k.lower().encode(), v.encode()) for k, v in (headers or {}).items()]
    if close:
        raw.append((b"connection", b"close"))
    await send({"type": "http.response.start", "status": status, "headers": raw})
    await send({"type": "http.response.body", "body": body})


class RefuseEncodedBodies:
    """ASGI middleware: 415 for a request body with a Content-Encoding (gzip, deflate...).

    Nothing here inflates request bodies; refusing them before a byte is read means a compressed
    bomb can never be inflated by a later layer either.
    """

    def __init__(self, app) -> None:
        self.app = app

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] == "http":
            headers = dict(scope.get("headers") or [])
            encoding = headers.get(b"content-encoding", b"identity").strip().lower()
            if encoding not in (b"", b"identity"):
                message = "compressed request bodies are not accepted: send the file as is"
                await send_error(send, 415, "unsupported_encoding", message)
                return
        await self.app(scope, receive, send)


class UploadStalled(Exception):
    """Raised from `receive` when a request body makes no progress, or too little (never an
    OSError/TimeoutError, which the app's own handlers would turn into a response first)."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class GuardUploads:
    """ASGI middleware for request bodies (POST/PUT/PATCH): at most `max_concurrent` read at once (the
    next is 503 + Retry-After before a byte is read), at most `per_client` of them (a quarter unless
    told) for one client (as app/services/clients.py names it: 429 + Retry-After), `timeout_s` at most
    between two chunks and, past the first `timeout_s`, at least `min_rate` bytes a second on average
    (408).

    A stalled or trickling client used to hold its connection, and the memory of what it had sent,
    for as long as it liked; one address trickling a byte every 10 s into 16 bodies held every slot,
    and every upload and search of every other client was 503 (red team, 2026-12-05). The slot is
    freed as soon as the body is complete: what follows (the query pool) has admission control of its
    own.
    """

    METHODS = ("POST", "PUT", "PATCH")
    DRAIN_BYTES = 1 << 20  # a refused body up to this size is read and dropped, so the 503 arrives

    def __init__(self, app, max_concurrent: int, timeout_s: float, retry_after_s: int = 5,
                 min_rate: float = 0.0, per_client: int | None = None) -> None:
        self.app = app
        self.max_concurrent = max_concurrent
        self.per_client = per_client if per_client is not None else max(1, max_concurrent // 4)
        self.timeout_s = timeout_s
        self.retry_after_s = retry_after_s
        self.min_rate = min_rate  # bytes a second, averaged from the start, checked past timeout_s
        self.active = 0
        self.by_client: dict[str, int] = {}

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http" or scope["method"] not in self.METHODS:
            await self.app(scope, receive, send)
            return
        if self.active >= self.max_concurrent:
            # a client still sending when the server closes gets a reset, not the 503: drop a small
            # body first (nothing is kept), close on a big or stalled one
            drained = await self._drain(receive)
            message = f"{self.max_concurrent} uploads are being received already; retry shortly"
            headers = {"Retry-After": str(self.retry_after_s)}
            await send_error(send, 503, "busy", message, headers, close=not drained)
            return
        client = current_client()
        if self.by_client.get(client, 0) >= self.per_client:
            drained = await self._drain(receive)
            message = f"{self.per_client} of your uploads are being received already; wait for them"
            await send_error(send, 429, "too_many_requests", message, {"Retry-After": str(RETRY_AFTER_S)},
                             close=not drained)
            return
        self.active += 1
        self.by_client[client] = self.by_client.get(client, 0) + 1
        state = {"reading": True, "started": False}
        start, received = time.monotonic(), 0

        def done_reading() -> None:
            if state["reading"]:
                state["reading"] = False
                self.active -= 1
                self.by_client[client] -= 1
                if not self.by_client[client]:
                    del self.by_client[client]

        async def timed_receive():
            nonlocal received
            if not state["reading"]:  # the body is in: waiting for a disconnect is not a stall
                return await receive()
            try:
                message = await asyncio.wait_for(receive(), self.timeout_s)
            except TimeoutError:
                stalled = f"no upload data for {self.timeout_s:g} s: the request was given up"
                raise UploadStalled(stalled) from None
            received += len(message.get("body", b""))
            if message["type"] != "http.request" or not message.get("more_body", False):
                done_reading()
            else:
                took = time.monotonic() - start
                if self.min_rate > 0 and took > self.timeout_s and received < self.min_rate * took:
                    raise UploadStalled(f"the upload arrived slower than {self.min_rate / 1024:g} KiB/s:"
                                        " the request was given up")
            return message

        async def tracking_send(message) -> None:
            if message["type"] == "http.response.start":
                state["started"] = True
            await send(message)

        try:
            await self.app(scope, timed_receive, tracking_send)
        except UploadStalled as exc:
            if not state["started"]:
                await send_error(send, 408, "upload_timeout", exc.message)
        finally:
            done_reading()

    async def _drain(self, receive) -> bool:
        return await drain(receive, self.timeout_s, self.DRAIN_BYTES)


async def drain(receive, timeout_s: float, limit: int) -> bool:
    """Read and discard a request body; True if it ended within `limit` bytes and the time limit."""
    size = 0
    while size <= limit:
        try:
            message = await asyncio.wait_for(receive(), timeout_s)
        except TimeoutError:
            return False
        if message["type"] != "http.request":
            return False
        size += len(message.get("body", b""))
        if not message.get("more_body", False):
            return size <= limit
    return False


def check_data_dir(data_dir: Path) -> None:
    """Refuse to start (ValueError, one line) on a data directory that cannot be created or written.

    A write probe rather than os.access: access() says yes to root on a read-only mount.
    """
    try:
        Path(data_dir).mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".write-probe.", dir=data_dir)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"cannot use the data directory {data_dir}: {exc.strerror or exc}") from None


# ids are SQLite INTEGERs: a larger number is a 422 from validation, not an OverflowError (500) in the driver
IdPath = Annotated[int, PathParam(ge=1, le=2**63 - 1, description="a model or job id")]
# a page offset beyond any real collection; unbounded, 2**64 overflowed the driver (500)
MAX_OFFSET = 10**9
OffsetQuery = Annotated[int, Query(ge=0, le=MAX_OFFSET, description="models to skip")]
