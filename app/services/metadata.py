"""Model metadata: standard JSON only, bounded, so that every stored row serialises back out.

Python's json module accepts more than JSON: NaN/Infinity, lone surrogate escapes ("\\ud800"),
integers of any length and nesting up to the interpreter's recursion limit. Any of those stored once
made every response holding the row fail (a 500 until it was deleted), so they are refused here,
before anything is stored, with the first offending path in the message.
"""

from __future__ import annotations

import json
import math
from typing import Any

from app.services.errors import InvalidInputError

MAX_METADATA_BYTES = 16 * 1024  # of the stored (compact) JSON text
MAX_DEPTH = 16  # objects/arrays inside each other
MAX_INT_DIGITS = 19  # int64 range, checked exactly below; stops 5000-digit parses early
INT_RANGE = (-(2**63), 2**63 - 1)


def _refuse(where: str, what: str) -> InvalidInputError:
    where = where if len(where) <= 60 else where[:57] + "..."
    return InvalidInputError(f"metadata{where}: {what}")


def _parse_int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_INT_DIGITS:
        raise _refuse("", f"an integer of {len(text)} digits (at most 64-bit integers)")
    return int(text)


def _parse_constant(name: str) -> float:
    raise _refuse("", f"{name} is not standard JSON")


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _refuse("", f"the key {key!r} appears twice")
        out[key] = value
    return out


def parse_metadata(raw: str | None) -> dict:
    """The multipart `metadata` field -> a dict that check_metadata accepts; InvalidInputError otherwise."""
    if raw is None or raw.strip() == "":
        return {}
    if len(raw.encode("utf-8", "surrogatepass")) > MAX_METADATA_BYTES:
        raise _refuse("", f"longer than {MAX_METADATA_BYTES} bytes")
    if raw.count("[") + raw.count("{") > 0 and _nesting(raw) > MAX_DEPTH:
        raise _refuse("", f"nested deeper than {MAX_DEPTH} levels")  # before json recurses into it
    try:
        value = json.loads(
            raw, parse_int=_parse_int, parse_constant=_parse_constant, object_pairs_hook=_no_duplicates
        )
    except json.JSONDecodeError as exc:
        raise InvalidInputError(f"metadata is not valid JSON: {exc.msg} at position {exc.pos}") from exc
    except RecursionError:
        raise _refuse("", f"nested deeper than {MAX_DEPTH} levels") from None
    if not isinstance(value, dict):
        raise InvalidInputError("metadata must be a JSON object")
    return check_metadata(value)


def _nesting(raw: str) -> int:
    """Deepest bracket nesting outside strings (a cheap scan; json.loads would recurse that deep)."""
    depth = deepest = 0
    in_string = escaped = False
    for ch in raw:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth -= 1
    return deepest


def check_metadata(value: dict) -> dict:
    """Refuse (InvalidInputError) anything that would not round-trip through standard JSON and UTF-8.

    Every door that stores metadata (the API, bulk ingest) passes through here via ingestion.submit.
    """
    if not isinstance(value, dict):
        raise InvalidInputError("metadata must be a JSON object")
    _walk(value, "", 1)
    text = json.dumps(value, allow_nan=False, ensure_ascii=False, separators=(",", ":"))
    if len(text.encode("utf-8")) > MAX_METADATA_BYTES:
        raise _refuse("", f"longer than {MAX_METADATA_BYTES} bytes")
    return value


def _walk(value: Any, where: str, depth: int) -> None:
    if isinstance(value, dict | list) and depth > MAX_DEPTH:
        raise _refuse(where, f"nested deeper than {MAX_DEPTH} levels")
    if isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                raise _refuse(where, "object keys must be strings")
            _check_text(key, where)
            _walk(item, f"{where}.{key}", depth + 1)
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _walk(item, f"{where}[{i}]", depth + 1)
    elif isinstance(value, str):
        _check_text(value, where)
    elif isinstance(value, bool) or value is None:
        return
    elif isinstance(value, int):
        if not INT_RANGE[0] <= value <= INT_RANGE[1]:
            raise _refuse(where, "an integer outside the 64-bit range")
    elif isinstance(value, float):
        if not math.isfinite(value):
            raise _refuse(where, "NaN and Infinity are not standard JSON")
    else:
        raise _refuse(where, f"a {type(value).__name__} is not a JSON value")


def _check_text(text: str, where: str) -> None:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:  # a lone surrogate ("\ud800"): not encodable, so not serialisable
        raise _refuse(where, "a lone surrogate (\\ud800-\\udfff) is not Unicode text") from None
