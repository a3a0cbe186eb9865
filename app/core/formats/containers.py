"""Zip containers (.zip uploads, .3mf): open with a cap on what they unpack to."""

from __future__ import annotations

import io
import zipfile
import zlib

from app.core.meshdata import Budget, InvalidMeshError

MAX_MEMBERS = 10_000


def open_zip(data: bytes, budget: Budget, what: str) -> zipfile.ZipFile:
    """A ZipFile whose declared unpacked size fits the budget; InvalidMeshError otherwise."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        members = archive.infolist()
    except (zipfile.BadZipFile, ValueError, OSError) as exc:
        raise InvalidMeshError(f"could not read the file as {what}: it is not a valid zip archive") from exc
    if len(members) > MAX_MEMBERS:
        raise InvalidMeshError(f"the {what} archive holds {len(members)} files, more than {MAX_MEMBERS}")
    unpacked = sum(m.file_size for m in members)
    if unpacked > budget.unpacked_bytes():
        raise InvalidMeshError(
            f"the {what} archive unpacks to {unpacked} bytes, more than the {budget.unpacked_bytes()} allowed"
        )
    if any(m.flag_bits & 0x1 for m in members):
        raise InvalidMeshError(f"the {what} archive is encrypted: upload it without a password")
    return archive


def read_member(archive: zipfile.ZipFile, name: str, what: str) -> bytes:
    try:
        return archive.read(name)
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, NotImplementedError, EOFError) as exc:
        raise InvalidMeshError(
            f"could not unpack '{name[:80]}' from the {what} archive: it is corrupt"
        ) from exc


def check_members(archive: zipfile.ZipFile, what: str) -> None:
    """Unpack every member once (within the budget open_zip checked) so that a damaged archive is named
    as such, not by zlib's words."""
    try:
        bad = archive.testzip()
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, NotImplementedError, EOFError):
        bad = "?"
    if bad is not None:
        raise InvalidMeshError(f"the {what} archive is corrupt: a file inside it does not unpack")
