"""The streaming multipart reader at its edges (issue 15 mutation pass): header names in any case and
order, parts kept apart, bytes that are not UTF-8, a repeated field, the byte limits at exactly the
limit and one past it, a declared length that is not a number, and the OpenAPI body it describes."""

from __future__ import annotations

import asyncio

import pytest

from app.api.uploads import MAX_FIELD_BYTES, multipart_body, read_form
from app.services.errors import InvalidInputError, PayloadTooLargeError
from tests.api.test_uploads import BOUNDARY, _request


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
