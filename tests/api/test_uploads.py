"""The streaming multipart reader: fields and files parsed; an oversized body refused before all is read."""

from __future__ import annotations

import asyncio

import pytest
from starlette.requests import Request

from app.api.uploads import MAX_FIELD_BYTES, human_size, multipart_body, read_form
from app.services.errors import InvalidInputError, PayloadTooLargeError

BOUNDARY = "xYzZy"


def _body(file_bytes: bytes, **fields: str) -> bytes:
    parts = [
        f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="{k}"\r\n\r\n{v}\r\n'.encode()
        for k, v in fields.items()
    ]
    parts.append(
        f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="file"; filename="m.obj"\r\n'
        "Content-Type: application/octet-stream\r\n\r\n".encode()
        + file_bytes
        + b"\r\n"
    )
    return b"".join(parts) + f"--{BOUNDARY}--\r\n".encode()


def _request(body: bytes, chunk: int = 1024, headers: dict | None = None) -> tuple[Request, list[int]]:
    """A request whose body arrives in chunks; `sent` counts the chunks the reader pulled."""
    sent: list[int] = []
    chunks = [body[i : i + chunk] for i in range(0, len(body), chunk)] or [b""]

    async def receive():
        i = len(sent)
        sent.append(i)
        return {"type": "http.request", "body": chunks[i], "more_body": i + 1 < len(chunks)}

    hdrs = {"content-type": f"multipart/form-data; boundary={BOUNDARY}", **(headers or {})}
    scope = {
        "type": "http",
        "method": "POST",
        "path": "/",
        "headers": [(k.encode(), v.encode()) for k, v in hdrs.items()],
    }
    return Request(scope, receive), sent


def test_fields_and_file_are_parsed():
    request, _ = _request(_body(b"v 0 0 0\n" * 100, name="n", label="cat"))
    form = asyncio.run(read_form(request, max_bytes=10_000))
    assert form.fields == {"name": "n", "label": "cat"}
    assert form.file("file") == ("m.obj", b"v 0 0 0\n" * 100)
    with pytest.raises(InvalidInputError):
        form.file("other")


def test_oversized_stream_is_refused_early_without_content_length():
    limit = 10_000
    body = _body(b"x" * 1_000_000)  # 100x the limit, ~1000 chunks
    request, sent = _request(body)
    with pytest.raises(PayloadTooLargeError):
        asyncio.run(read_form(request, max_bytes=limit))
    assert len(sent) * 1024 <= limit + MAX_FIELD_BYTES + 1024  # stopped at the limit, not at the end


def test_declared_length_over_the_limit_is_refused_before_reading():
    request, sent = _request(_body(b"x" * 100), headers={"content-length": str(10**9)})
    with pytest.raises(PayloadTooLargeError):
        asyncio.run(read_form(request, max_bytes=10_000))
    assert sent == []


def test_the_413_states_the_limit_in_binary_units_and_in_bytes():
    request, _ = _request(_body(b"x" * 100), headers={"content-length": str(10**9)})
    with pytest.raises(PayloadTooLargeError) as refused:
        asyncio.run(read_form(request, max_bytes=50 * 1024 * 1024))  # the default limit
    assert str(refused.value) == "the upload is larger than the limit of 50 MiB (52428800 bytes)"


@pytest.mark.parametrize(("n", "text"), [
    (0, "0 bytes"), (1, "1 byte"), (1023, "1023 bytes"), (1024, "1 KiB"), (1536, "1.5 KiB"),
    (1024 * 1024 - 52, "1023.9 KiB"), (1024 * 1024 - 40, "1 MiB"),  # 1023.96 KiB prints as 1 MiB
    (50 * 1024 * 1024, "50 MiB"), (50 * 1024 * 1024 + 60_000, "50.1 MiB"), (3 * 1024**4, "3 TiB"),
])
def test_human_size_uses_binary_units_with_at_most_one_decimal(n, text):
    assert human_size(n) == text


def test_not_multipart_is_a_clear_error():
    scope = {
        "type": "http",
        "method": "POST",
        "path": "/",
        "headers": [(b"content-type", b"application/json")],
    }
    with pytest.raises(InvalidInputError, match="multipart/form-data"):
        asyncio.run(read_form(Request(scope), max_bytes=10))


MALFORMED = [
    b"garbage",
    f"--{BOUNDARY}X".encode(),
    f"--{BOUNDARY}\r\nContent-Disposition form-data\r\n\r\nx\r\n--{BOUNDARY}--\r\n".encode(),
    f"--{BOUNDARY}\r\n\x00\x01\r\n\r\n".encode(),
]


@pytest.mark.parametrize("body", MALFORMED)
def test_a_malformed_multipart_body_is_invalid_input(body):
    """Not a parser exception (a 500) but InvalidInputError (issue 15 item 1)."""
    with pytest.raises(InvalidInputError, match="malformed multipart"):
        asyncio.run(read_form(_request(body)[0], 10_000))


def test_every_route_reading_a_form_answers_a_malformed_body_with_422(settings):
    from fastapi.testclient import TestClient

    from app.main import create_app

    headers = {"content-type": f"multipart/form-data; boundary={BOUNDARY}"}
    with TestClient(create_app(settings.model_copy(update={"workers": 0}))) as client:
        for route in ("/models", "/search", "/web/preview.png"):
            for body in MALFORMED:
                r = client.post(route, content=body, headers=headers)
                assert r.status_code == 422 and "malformed multipart" in r.json()["error"]["message"], (
                    route,
                    body,
                    r.text[:200],
                )


# The streaming multipart reader at its edges: header names in any case and
# order, parts kept apart, bytes that are not UTF-8, a repeated field, the byte limits at exactly the
# limit and one past it, a declared length that is not a number, and the OpenAPI body it describes.


def _part(headers: list[bytes], content: bytes) -> bytes:
    return f"--{BOUNDARY}\r\n".encode() + b"".join(h + b"\r\n" for h in headers) + b"\r\n" + content + b"\r\n"


def _field(name: bytes, value: bytes) -> bytes:
    return _part([b'Content-Disposition: form-data; name="' + name + b'"'], value)


def _file(content: bytes, filename: bytes = b"m.obj", name: bytes = b"file") -> bytes:
    return _part(
        [
            b"Content-Type: application/octet-stream",  # before the disposition: headers kept apart
            b'Content-Disposition: form-data; name="' + name + b'"; filename="' + filename + b'"',
        ],
        content,
    )


def _end(*parts: bytes) -> bytes:
    return b"".join(parts) + f"--{BOUNDARY}--\r\n".encode()


def _read(body: bytes, max_bytes: int = 10_000, chunk: int = 7, headers: dict | None = None):
    """read_form over a body sent in `chunk`-byte pieces (parts and headers split across chunks)."""
    request, _ = _request(body, chunk=chunk, headers=headers)
    return asyncio.run(read_form(request, max_bytes=max_bytes))


def test_parts_headers_and_contents_are_kept_apart():
    form = _read(_end(_field(b"name", b"a chair"), _file(b"v 1 2 3\n" * 50), _field(b"label", b"chair")))
    assert form.fields == {"name": "a chair", "label": "chair"}
    assert form.files == {"file": ("m.obj", b"v 1 2 3\n" * 50)}
    assert form.file() == ("m.obj", b"v 1 2 3\n" * 50)  # "file" is the default


def test_header_names_are_case_insensitive():
    body = _end(_part([b'CONTENT-DISPOSITION: form-data; name="label"'], b"x"), _file(b"1", name=b"mesh"))
    form = _read(body)
    assert form.fields == {"label": "x"} and form.file("mesh") == ("m.obj", b"1")


def test_each_part_has_its_own_headers():
    """A part without a Content-Disposition does not inherit the previous part's name."""
    form = _read(_end(_field(b"label", b"a"), _part([b"Content-Type: text/plain"], b"b"), _file(b"1")))
    assert form.fields == {"label": "a", "": "b"} and form.file() == ("m.obj", b"1")


def test_a_missing_file_field_is_named_in_words():
    form = _read(_end(_field(b"name", b"n")))
    with pytest.raises(InvalidInputError, match="^the multipart form has no file field 'file'$"):
        form.file()


def test_bytes_that_are_not_utf8_are_replaced_not_refused():
    body = _end(_field(b"na\xffme", b"caf\xe9"), _file(b"\xff\xfe", filename=b"m\xff.obj"))
    form = _read(body)
    assert form.fields == {"na\ufffdme": "caf\ufffd"}
    assert form.files == {"file": ("m\ufffd.obj", b"\xff\xfe")}  # the content stays bytes


@pytest.mark.parametrize(
    "parts",
    [
        [_field(b"label", b"a"), _field(b"label", b"b")],
        [_file(b"1"), _file(b"2", filename=b"other.obj")],
        [_field(b"file", b"a"), _file(b"2")],
        [_file(b"2"), _field(b"file", b"a")],
    ],
)
def test_a_repeated_field_is_refused_not_silently_overwritten(parts):
    with pytest.raises(InvalidInputError, match="appears more than once"):
        _read(_end(*parts))


def test_a_repeated_field_names_at_most_100_characters_of_it():
    name = b"n" * 300
    with pytest.raises(InvalidInputError) as err:
        _read(_end(_field(name, b"a"), _field(name, b"b")))
    assert err.value.message == f"the form field {'n' * 100!r} appears more than once"


def test_a_text_field_may_be_exactly_max_field_bytes_and_not_one_more():
    value = b"x" * MAX_FIELD_BYTES
    form = _read(_end(_field(b"metadata", value), _file(b"1")), max_bytes=1000, chunk=4096)
    assert form.fields["metadata"] == value.decode()
    with pytest.raises(
        InvalidInputError, match=f"^form field 'metadata' is longer than {MAX_FIELD_BYTES} bytes$"
    ):
        _read(_end(_field(b"metadata", value + b"x"), _file(b"1")), max_bytes=1000, chunk=4096)


def test_a_file_may_be_exactly_max_bytes_and_not_one_more():
    assert _read(_end(_file(b"y" * 1000)), max_bytes=1000).file() == ("m.obj", b"y" * 1000)
    with pytest.raises(PayloadTooLargeError, match="^the upload is larger than the limit of 999 bytes$"):
        _read(_end(_file(b"y" * 1000)), max_bytes=999)


def test_the_stream_may_reach_max_bytes_plus_the_field_allowance_and_not_pass_it():
    """A form of one full text field and a file: max_bytes + MAX_FIELD_BYTES of body is still read."""
    body = _end(_field(b"metadata", b"m" * MAX_FIELD_BYTES), _file(b"f" * 100))
    limit = len(body) - MAX_FIELD_BYTES
    assert _read(body, max_bytes=limit, chunk=1000).file() == ("m.obj", b"f" * 100)
    with pytest.raises(PayloadTooLargeError, match=f"limit of {limit - 1} bytes$"):
        _read(body, max_bytes=limit - 1, chunk=1000)


@pytest.mark.parametrize("declared", ["abc", "-1", ""])
def test_a_declared_length_that_is_not_a_number_is_ignored(declared):
    form = _read(_end(_file(b"z")), headers={"content-length": declared})
    assert form.file() == ("m.obj", b"z")


def test_a_declared_length_at_the_limit_is_read():
    body = _end(_file(b"z" * 10))
    form = _read(body, max_bytes=100, headers={"content-length": str(100 + MAX_FIELD_BYTES)})
    assert form.file() == ("m.obj", b"z" * 10)
    with pytest.raises(PayloadTooLargeError, match="limit of 100 bytes$"):
        _read(body, max_bytes=100, headers={"content-length": str(101 + MAX_FIELD_BYTES)})


@pytest.mark.parametrize(
    "content_type",
    [
        "multipart/form-data",  # no boundary
        f"multipart/mixed; boundary={BOUNDARY}",
        f"text/plain; boundary={BOUNDARY}",
        "",
    ],
)
def test_anything_but_multipart_form_data_with_a_boundary_is_refused(content_type):
    with pytest.raises(InvalidInputError, match="^send the mesh as multipart/form-data with a 'file' field$"):
        _read(_end(_file(b"z")), headers={"content-type": content_type})


def test_a_body_that_stops_mid_part_does_not_yield_the_unfinished_part():
    """python-multipart's finalize checks nothing (yet): the cut part never ends, so it is not taken."""
    form = _read(_end(_field(b"label", b"a"), _file(b"z"))[:-10])
    assert form.fields == {"label": "a"} and form.files == {}


def test_the_openapi_body_requires_a_binary_file_and_keeps_the_other_fields():
    body = multipart_body("the mesh", label={"type": "string"})
    assert body == {
        "requestBody": {
            "required": True,
            "content": {
                "multipart/form-data": {
                    "schema": {
                        "type": "object",
                        "required": ["file"],
                        "properties": {
                            "file": {"type": "string", "format": "binary", "description": "the mesh"},
                            "label": {"type": "string"},
                        },
                    }
                }
            },
        }
    }


def test_a_form_of_many_parts_is_refused_once_it_passes_max_parts_and_reading_stops():
    """930,000 empty fields in 50 MiB took the API process to 1.7 GB; MAX_PARTS parts pass, one more is
    refused before the rest of the body is read."""
    from app.api.uploads import MAX_PARTS

    fields = [_field(f"f{i}".encode(), b"") for i in range(MAX_PARTS - 1)]
    form = _read(_end(*fields, _file(b"v 0 0 0\n")), chunk=4096)
    assert len(form.fields) == MAX_PARTS - 1 and form.file()[1] == b"v 0 0 0\n"
    many = _end(*[_field(f"f{i}".encode(), b"") for i in range(20_000)], _file(b"v 0 0 0\n"))
    request, sent = _request(many, chunk=4096)
    with pytest.raises(InvalidInputError, match=f"more than {MAX_PARTS} parts"):
        asyncio.run(read_form(request, max_bytes=len(many)))
    assert len(sent) <= 2  # the refusal came within the first chunks, not after the whole body


def test_a_boundary_the_parser_refuses_is_invalid_input_not_a_500():
    """python-multipart's constructor refuses a boundary over 256 bytes (FormParserError)."""
    long = "a" * 2000
    body = (f"--{long}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"m.obj\"\r\n\r\n"
            f"v\r\n--{long}--\r\n")
    request, _ = _request(body.encode(), headers={"content-type": f"multipart/form-data; boundary={long}"})
    with pytest.raises(InvalidInputError, match="malformed multipart"):
        asyncio.run(read_form(request, max_bytes=100_000))


def test_a_client_gone_mid_body_is_one_quiet_line_not_a_500(settings, caplog):
    """The connection closes after part of the body: ClientDisconnect answered 400 client_disconnected,
    logged once at INFO with no traceback (aborted uploads in a loop wrote megabytes of tracebacks)."""
    import logging

    from app.main import create_app

    app = create_app(settings.model_copy(update={"workers": 0}))
    messages = [{"type": "http.request", "body": f"--{BOUNDARY}\r\n".encode(), "more_body": True},
                {"type": "http.disconnect"}]
    sent: list[dict] = []

    async def receive():
        return messages.pop(0) if messages else {"type": "http.disconnect"}

    async def send(message):
        sent.append(message)

    scope = {"type": "http", "method": "POST", "path": "/search", "raw_path": b"/search", "root_path": "",
             "query_string": b"", "scheme": "http", "server": ("127.0.0.1", 80), "client": ("127.0.0.9", 5),
             "http_version": "1.1",
             "headers": [(b"content-type", f"multipart/form-data; boundary={BOUNDARY}".encode()),
                         (b"host", b"x")]}

    async def run():
        async with app.router.lifespan_context(app):
            await app(scope, receive, send)

    with caplog.at_level(logging.INFO):
        asyncio.run(run())
    start = next(m for m in sent if m["type"] == "http.response.start")
    assert start["status"] == 400
    assert any("client went away during POST /search" in r.getMessage() for r in caplog.records)
    assert not any(r.exc_info for r in caplog.records if r.levelno >= logging.ERROR)
