"""The streaming multipart reader: fields and files parsed; an oversized body refused before all is read."""

from __future__ import annotations

import asyncio

import pytest
from starlette.requests import Request

from app.api.uploads import MAX_FIELD_BYTES, human_size, read_form
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
