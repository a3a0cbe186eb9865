"""Streaming multipart reader: refuses an upload (413) as soon as it passes the size limit.

FastAPI's UploadFile spools the whole body before the handler runs; this reads the request stream
chunk by chunk, so an oversized upload costs at most `max_bytes` of memory and reading.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fastapi import Request
from python_multipart.exceptions import FormParserError
from python_multipart.multipart import MultipartParser, parse_options_header

from app.services.errors import InvalidInputError, PayloadTooLargeError

MAX_FIELD_BYTES = 64 * 1024  # text fields (name, label, metadata)
# parts of one form: the widest form has a file and 5 text fields. Each part costs a few hundred bytes
# of Python objects and its parsing runs on the event loop: 930,000 empty fields in a 50 MiB body took
# the API process to 1.7 GB and every other request's latency with it (red team, 2026-12-05)
MAX_PARTS = 16


@dataclass
class UploadForm:
    fields: dict[str, str] = field(default_factory=dict)
    files: dict[str, tuple[str, bytes]] = field(default_factory=dict)  # name -> (filename, content)

    def file(self, name: str = "file") -> tuple[str, bytes]:
        if name not in self.files:
            raise InvalidInputError(f"the multipart form has no file field {name!r}")
        return self.files[name]


async def read_form(request: Request, max_bytes: int) -> UploadForm:
    ctype, params = parse_options_header(request.headers.get("content-type", ""))
    if ctype != b"multipart/form-data" or b"boundary" not in params:
        raise InvalidInputError("send the mesh as multipart/form-data with a 'file' field")
    declared = request.headers.get("content-length")
    if declared and declared.isdigit() and int(declared) > max_bytes + MAX_FIELD_BYTES:
        raise _too_large(max_bytes)
    form = UploadForm()
    state: dict = {"headers": {}, "field": b"", "value": b""}
    parts: list[bytearray] = []
    total = 0

    def on_part_begin() -> None:
        state["headers"] = {}
        parts.clear()
        state["parts"] = state.get("parts", 0) + 1
        if state["parts"] > MAX_PARTS:
            raise InvalidInputError(f"the multipart form has more than {MAX_PARTS} parts; send the file and"
                                    " the named fields only")

    def on_header_field(data: bytes, start: int, end: int) -> None:
        state["field"] += data[start:end]

    def on_header_value(data: bytes, start: int, end: int) -> None:
        state["value"] += data[start:end]

    def on_header_end() -> None:
        state["headers"][state["field"].lower()] = state["value"]
        state["field"], state["value"] = b"", b""

    def on_part_data(data: bytes, start: int, end: int) -> None:
        parts.append(bytearray(data[start:end]))

    def on_part_end() -> None:
        _, disp = parse_options_header(state["headers"].get(b"content-disposition", b""))
        name = disp.get(b"name", b"").decode("utf-8", "replace")
        content = b"".join(parts)
        if name in form.files or name in form.fields:  # the last one would silently win
            raise InvalidInputError(f"the form field {name[:100]!r} appears more than once")
        if b"filename" in disp:
            form.files[name] = (disp[b"filename"].decode("utf-8", "replace"), content)
        else:
            if len(content) > MAX_FIELD_BYTES:
                raise InvalidInputError(f"form field {name!r} is longer than {MAX_FIELD_BYTES} bytes")
            form.fields[name] = content.decode("utf-8", "replace")

    callbacks = {
        "on_part_begin": on_part_begin,
        "on_header_field": on_header_field,
        "on_header_value": on_header_value,
        "on_header_end": on_header_end,
        "on_part_data": on_part_data,
        "on_part_end": on_part_end,
    }
    # FormParserError: every error python-multipart raises for a body (a boundary over 256 bytes is
    # refused by the constructor, not by parsing): the client's input, a 422, never a 500
    try:
        parser = MultipartParser(params[b"boundary"], callbacks)  # type: ignore[arg-type]
    except FormParserError as exc:
        raise InvalidInputError(f"malformed multipart body: {exc}") from exc
    async for chunk in request.stream():
        total += len(chunk)
        if total > max_bytes + MAX_FIELD_BYTES:
            raise _too_large(max_bytes)
        try:
            parser.write(chunk)
        except FormParserError as exc:
            raise InvalidInputError(f"malformed multipart body: {exc}") from exc
    try:
        parser.finalize()
    except FormParserError as exc:
        raise InvalidInputError(f"malformed multipart body: {exc}") from exc
    for _, content in form.files.values():
        if len(content) > max_bytes:
            raise _too_large(max_bytes)
    return form


def _too_large(max_bytes: int) -> PayloadTooLargeError:
    limit = human_size(max_bytes)
    exact = "" if limit.endswith(" bytes") else f" ({max_bytes} bytes)"
    return PayloadTooLargeError(f"the upload is larger than the limit of {limit}{exact}")


def human_size(n: int) -> str:
    """Bytes in binary units, as the settings are written (50 * 1024 * 1024 -> '50 MiB'): at most one
    decimal, trailing zeros dropped; below 1 KiB, in bytes."""
    value, unit = float(n), "bytes"
    for bigger in ("KiB", "MiB", "GiB", "TiB"):
        if round(value, 1) < 1024:  # compare what is printed: 1023.96 KiB reads as 1 MiB, not 1024 KiB
            break
        value, unit = value / 1024, bigger
    if unit == "bytes":
        return "1 byte" if n == 1 else f"{n} bytes"
    return f"{value:.1f}".rstrip("0").rstrip(".") + f" {unit}"


def multipart_body(file_description: str, **fields: dict) -> dict:
    """OpenAPI `requestBody` of a multipart form with a required mesh `file` and optional `fields`.

    The routes read the form themselves (streaming, with a byte limit), so FastAPI cannot infer it.
    """
    properties = {"file": {"type": "string", "format": "binary", "description": file_description}, **fields}
    schema = {"type": "object", "required": ["file"], "properties": properties}
    return {"requestBody": {"required": True, "content": {"multipart/form-data": {"schema": schema}}}}
