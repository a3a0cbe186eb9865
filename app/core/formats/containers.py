"""Zip containers (.zip uploads, .3mf, a zipped COLLADA): open with a cap on what they unpack to.

Every upload whose bytes are a zip goes through open_zip, whatever its name, so that no reader (nor a
library behind it) unpacks an archive that was not checked first.
"""

from __future__ import annotations

import io
import struct
import zipfile
import zlib

from app.core.meshdata import Budget, InvalidMeshError

MAX_MEMBERS = 10_000
# what Python's zipfile unpacks: stored, deflate, bzip2, lzma
METHODS = {zipfile.ZIP_STORED: "stored", zipfile.ZIP_DEFLATED: "deflate", 12: "bzip2", 14: "lzma"}
MAX_VERSION = 63  # zip 6.3, the newest format zipfile reads
_READ_ERRORS = (
    zipfile.BadZipFile,
    zlib.error,
    ValueError,
    OSError,
    NotImplementedError,
    EOFError,
    struct.error,
)


def is_zip(data: bytes) -> bool:
    """True when the bytes are a zip archive (a local file header or an empty archive's end record)."""
    return data[:4] in (b"PK\x03\x04", b"PK\x05\x06")


def open_zip(data: bytes, budget: Budget, what: str) -> zipfile.ZipFile:
    """A ZipFile whose declared unpacked size fits the budget and whose members this Python can unpack;
    InvalidMeshError naming the problem otherwise."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        members = archive.infolist()
    except NotImplementedError as exc:  # zipfile refuses a newer format version while listing
        raise InvalidMeshError(
            f"the {what} archive needs a newer zip format than shapebag reads ({exc}): re-zip it with"
            " standard deflate compression"
        ) from exc
    except _READ_ERRORS as exc:
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
    for m in members:
        if m.compress_type not in METHODS:
            raise InvalidMeshError(
                f"'{m.filename[:80]}' in the {what} archive uses zip compression method {m.compress_type},"
                " which shapebag does not unpack: re-zip it with standard deflate compression"
            )
        if m.extract_version > MAX_VERSION:
            raise InvalidMeshError(
                f"'{m.filename[:80]}' in the {what} archive needs zip version {m.extract_version / 10:.1f},"
                f" newer than the {MAX_VERSION / 10:.1f} shapebag reads: re-zip it with standard deflate"
            )
    return archive


def read_member(archive: zipfile.ZipFile, name: str, what: str) -> bytes:
    try:
        return archive.read(name)
    except _READ_ERRORS as exc:
        raise InvalidMeshError(
            f"could not unpack '{name[:80]}' from the {what} archive: it is corrupt"
        ) from exc


def check_members(archive: zipfile.ZipFile, what: str) -> None:
    """Unpack every member once (within the budget open_zip checked) so that a damaged archive is named
    as such, not by zlib's words."""
    try:
        bad = archive.testzip()
    except _READ_ERRORS:
        bad = "?"
    if bad is not None:
        raise InvalidMeshError(f"the {what} archive is corrupt: a file inside it does not unpack")
