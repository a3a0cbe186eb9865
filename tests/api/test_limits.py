"""app/api/limits.py's middleware and checks driven directly, without a server: GuardUploads' slots, drain
and stall answers, RefuseEncodedBodies, send_error's framing, the text and file-name rules at their
edges, and the data-directory probe."""

from __future__ import annotations

import asyncio
import json
import re
from pathlib import Path

import pytest

from app.api import limits
from app.api.uploads import UploadForm
from app.core.meshdata import UnsupportedFormatError
from app.services.errors import InvalidInputError

Message = dict


class Wire:
    """An ASGI receive/send pair: `chunks` are the body (None = the client stalls forever)."""

    def __init__(self, chunks: list[bytes] | None, disconnect: bool = False) -> None:
        self.queue: list[Message] = []
        if chunks is not None:
            for i, c in enumerate(chunks):
                self.queue.append({"type": "http.request", "body": c, "more_body": i < len(chunks) - 1})
        if disconnect:
            self.queue = [{"type": "http.disconnect"}]
        self.stall = chunks is None
        self.sent: list[Message] = []

    async def receive(self) -> Message:
        if self.stall or not self.queue:
            await asyncio.sleep(3600)
        return self.queue.pop(0)

    async def send(self, message: Message) -> None:
        self.sent.append(message)

    def response(self) -> tuple[int, dict[bytes, bytes], dict]:
        start, body = self.sent[0], self.sent[1]
        return start["status"], dict(start["headers"]), json.loads(body["body"])


def _scope(method: str = "POST", headers: list | None = None) -> dict:
    return {"type": "http", "method": method, "headers": headers or []}


async def _echo_app(scope, receive, send) -> None:
    """Reads the whole body, answers 200 with its length."""
    size = 0
    while True:
        m = await receive()
        size += len(m.get("body", b""))
        if not m.get("more_body", False):
            break
    await limits.send_error(send, 200, "ok", str(size), close=False)


# --- GuardUploads -----------------------------------------------------------------------------


def test_a_body_is_passed_on_and_its_slot_freed():
    guard = limits.GuardUploads(_echo_app, max_concurrent=1, timeout_s=5)
    wire = Wire([b"ab", b"cde"])
    asyncio.run(guard(_scope(), wire.receive, wire.send))
    status, headers, body = wire.response()
    assert (status, body["error"]["message"]) == (200, "5")
    assert guard.active == 0


@pytest.mark.parametrize("method", ["GET", "DELETE"])
def test_bodiless_methods_take_no_slot(method):
    seen = []

    async def app(scope, receive, send):
        seen.append(guard.active)

    guard = limits.GuardUploads(app, max_concurrent=0, timeout_s=5)  # no slot at all
    asyncio.run(guard(_scope(method), Wire([]).receive, Wire([]).send))
    assert seen == [0]


def test_the_slot_is_held_while_the_body_is_read():
    seen = []

    async def app(scope, receive, send):
        seen.append(guard.active)
        await receive()
        seen.append(guard.active)

    guard = limits.GuardUploads(app, max_concurrent=2, timeout_s=5)
    wire = Wire([b"x"])
    asyncio.run(guard(_scope(), wire.receive, wire.send))
    assert seen == [1, 0] and guard.active == 0


@pytest.mark.parametrize(
    ("chunks", "closes"),
    [([b"a" * 10, b"b" * 10], False), ([b"a" * limits.GuardUploads.DRAIN_BYTES], False), (None, True)],
)
def test_a_full_house_answers_503_drains_small_bodies_closes_on_stalled(chunks, closes):
    guard = limits.GuardUploads(_echo_app, max_concurrent=2, timeout_s=0.05, retry_after_s=7)
    guard.active = 2
    wire = Wire(chunks)
    asyncio.run(guard(_scope(), wire.receive, wire.send))
    status, headers, body = wire.response()
    assert status == 503 and body["error"]["code"] == "busy"
    assert body["error"]["message"] == "2 uploads are being received already; retry shortly"
    assert headers[b"retry-after"] == b"7"
    assert (headers.get(b"connection") == b"close") is closes
    assert guard.active == 2


def test_drain_bounds():
    guard = limits.GuardUploads(_echo_app, max_concurrent=1, timeout_s=0.05)
    big = limits.GuardUploads.DRAIN_BYTES
    assert asyncio.run(guard._drain(Wire([b"a" * big]).receive)) is True
    assert asyncio.run(guard._drain(Wire([b"a" * (big + 1)]).receive)) is False
    assert asyncio.run(guard._drain(Wire([b"a" * big, b"b"]).receive)) is False
    assert asyncio.run(guard._drain(Wire([b"a" * 10, b""]).receive)) is True
    assert asyncio.run(guard._drain(Wire(None).receive)) is False
    assert asyncio.run(guard._drain(Wire([], disconnect=True).receive)) is False


def test_a_stalled_body_is_408_and_frees_the_slot():
    guard = limits.GuardUploads(_echo_app, max_concurrent=1, timeout_s=0.05)
    wire = Wire(None)
    asyncio.run(guard(_scope(), wire.receive, wire.send))
    status, headers, body = wire.response()
    assert (status, body["error"]["code"]) == (408, "upload_timeout")
    assert body["error"]["message"] == "no upload data for 0.05 s: the request was given up"
    assert headers[b"connection"] == b"close" and guard.active == 0


def test_a_stall_after_the_answer_started_sends_nothing_more():
    async def app(scope, receive, send):
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await receive()

    guard = limits.GuardUploads(app, max_concurrent=1, timeout_s=0.05)
    wire = Wire(None)
    asyncio.run(guard(_scope(), wire.receive, wire.send))
    assert [m["type"] for m in wire.sent] == ["http.response.start"] and guard.active == 0


def test_after_the_body_waiting_is_no_stall():
    async def app(scope, receive, send):
        await receive()  # the whole body
        assert (await receive())["type"] == "http.disconnect"  # waits past timeout_s: no 408

    async def receive_then_late_disconnect(queue=[{"type": "http.request", "body": b"x"}]):  # noqa: B006
        if queue:
            return queue.pop()
        await asyncio.sleep(0.1)
        return {"type": "http.disconnect"}

    guard = limits.GuardUploads(app, max_concurrent=1, timeout_s=0.02)
    wire = Wire([])
    asyncio.run(guard(_scope(), receive_then_late_disconnect, wire.send))
    assert wire.sent == [] and guard.active == 0


# --- RefuseEncodedBodies, send_error ----------------------------------------------------------


@pytest.mark.parametrize("encoding", [b"gzip", b" GZIP ", b"deflate"])
def test_encoded_bodies_are_415(encoding):
    reached = []
    mw = limits.RefuseEncodedBodies(lambda *a: reached.append(a))
    wire = Wire([])
    asyncio.run(mw(_scope(headers=[(b"content-encoding", encoding)]), wire.receive, wire.send))
    status, headers, body = wire.response()
    assert (status, body["error"]["code"]) == (415, "unsupported_encoding") and not reached


@pytest.mark.parametrize("headers", [[], [(b"content-encoding", b"identity")], [(b"content-encoding", b"")]])
def test_plain_bodies_pass(headers):
    reached = []

    async def app(scope, receive, send):
        reached.append(scope)

    asyncio.run(limits.RefuseEncodedBodies(app)(_scope(headers=headers), Wire([]).receive, Wire([]).send))
    assert len(reached) == 1


def test_send_error_frames_the_body():
    wire = Wire([])
    asyncio.run(limits.send_error(wire.send, 429, "c", "m", {"X-Thing": "v"}, close=False))
    start, body = wire.sent
    assert start["type"] == "http.response.start" and body["type"] == "http.response.body"
    headers = dict(start["headers"])
    assert headers[b"content-type"] == b"application/json" and headers[b"x-thing"] == b"v"
    assert int(headers[b"content-length"]) == len(body["body"]) and b"connection" not in headers
    assert json.loads(body["body"]) == {"error": {"code": "c", "message": "m"}}


# --- form and file-name rules, data dir -------------------------------------------------------


def test_text_fields_at_their_length_limit():
    limits.check_form(UploadForm(fields={"name": "n" * limits.MAX_TEXT_CHARS, "label": "l"}))
    for field_name in limits.TEXT_FIELDS:
        with pytest.raises(InvalidInputError, match=f"^{field_name}: longer than 200 characters$"):
            limits.check_form(UploadForm(fields={field_name: "n" * 201}))


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("a\x1bb", "a control character (U+001B)"),
        ("a\u202eb", "an invisible formatting character (U+202E)"),
        ("a\ud800b", "a surrogate (U+D800)"),
        ("a\ue000b", "a private-use character (U+E000)"),
        ("a\ufffdb", "bytes that are not valid UTF-8"),
    ],
)
def test_odd_characters_are_named(text, said):
    with pytest.raises(InvalidInputError, match=f"^{re.escape('label: contains ' + said)}$"):
        limits.check_form(UploadForm(fields={"name": "ok", "label": text}))
    with pytest.raises(InvalidInputError, match="the file name contains"):
        limits.check_form(UploadForm(files={"file": (text + ".obj", b"")}))


def test_the_file_field_is_the_one_named():
    form = UploadForm(files={"query": ("../x.obj", b"")})
    limits.check_form(form)  # not the default field: not checked
    with pytest.raises(InvalidInputError, match="plain name"):
        limits.check_form(form, file_field="query")


@pytest.mark.parametrize("name", [".", "..", "..obj", "a/b.obj", "a\\b.obj"])
def test_paths_are_not_file_names(name):
    with pytest.raises(InvalidInputError, match=r"^the file name must be a plain name"):
        limits.check_filename(name)


@pytest.mark.parametrize("name", ["a.obj", ".hidden.obj", "a..b.obj", "x" * 251 + ".obj"])
def test_plain_names_pass(name):
    assert limits.check_filename(name) == name


def test_an_unusable_data_dir_is_one_line(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(ValueError, match=rf"^cannot use the data directory {blocker}/sub: "):
        limits.check_data_dir(blocker / "sub")
    limits.check_data_dir(tmp_path / "new" / "dir")
    assert (tmp_path / "new" / "dir").is_dir() and list((tmp_path / "new" / "dir").iterdir()) == []


def test_drain_edges_exactly_full_and_no_more_body_key():
    guard = limits.GuardUploads(_echo_app, max_concurrent=1, timeout_s=0.05)
    big = limits.GuardUploads.DRAIN_BYTES
    # exactly DRAIN_BYTES, then the (empty) end of the body: still a drained body
    assert asyncio.run(guard._drain(Wire([b"a" * big, b""]).receive)) is True

    async def one_message_without_more_body():  # ASGI: a missing more_body means False
        return {"type": "http.request", "body": b"x"}

    assert asyncio.run(guard._drain(one_message_without_more_body)) is True


def test_a_long_file_name_is_refused_naming_the_limit_and_the_format_is_the_extension():
    with pytest.raises(InvalidInputError, match="^the file name is longer than 255 characters$"):
        limits.check_filename("x" * 252 + ".obj")
    assert limits.upload_format("Chair.OBJ") == "obj"
    with pytest.raises(UnsupportedFormatError):
        limits.upload_format("chair.docx")


def test_other_scopes_pass_through_the_guard_untouched():
    seen = []

    async def app(scope, receive, send):
        seen.append(scope)

    scope = {"type": "lifespan"}
    asyncio.run(limits.GuardUploads(app, max_concurrent=1, timeout_s=5)(scope, None, None))
    assert seen == [scope] and seen[0] is scope


def test_the_data_dir_check_accepts_an_existing_dir_and_probes_the_dir_itself(tmp_path):
    limits.check_data_dir(tmp_path)
    limits.check_data_dir(tmp_path)  # existing: fine, twice
    assert list(tmp_path.iterdir()) == []
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(ValueError, match=rf"^cannot use the data directory {blocker}/sub: Not a directory$"):
        limits.check_data_dir(blocker / "sub")
    with pytest.raises(ValueError, match="^cannot use the data directory /proc: "):
        limits.check_data_dir(Path("/proc"))  # no file can be made there, even as root


def test_the_415_says_why_and_a_plain_body_reaches_the_app_on_the_same_wire():
    wire = Wire([])
    asyncio.run(
        limits.RefuseEncodedBodies(_echo_app)(
            _scope(headers=[(b"content-encoding", b"br")]), wire.receive, wire.send
        )
    )
    assert (
        wire.response()[2]["error"]["message"]
        == "compressed request bodies are not accepted: send the file as is"
    )
    for middleware in (
        limits.RefuseEncodedBodies,
        lambda app: limits.GuardUploads(app, max_concurrent=1, timeout_s=5),
    ):
        seen = []

        async def app(scope, receive, send, seen=seen):
            seen.append(scope)
            await _echo_app(scope, receive, send)

        scope, wire = _scope(), Wire([b"abc", b"de"])
        asyncio.run(middleware(app)(scope, wire.receive, wire.send))
        assert seen == [scope] and seen[0] is scope
        assert wire.response()[0] == 200 and wire.response()[2]["error"]["message"] == "5"
