"""Helpers the text and binary readers share: number parsing with per-line widths, polygon fans."""

from __future__ import annotations

import warnings

import numpy as np

from app.core.meshdata import InvalidMeshError

BOM = b"\xef\xbb\xbf"


def text_lines(data: bytes) -> bytes:
    """Drop a UTF-8 byte-order mark and turn CR-LF and CR-only line ends into LF."""
    if data.startswith(BOM):
        data = data[len(BOM) :]
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    return data


def numbers(lines: list[bytes], what: str) -> tuple[np.ndarray, np.ndarray]:
    """Whitespace-separated numbers of each line -> (values (sum w,) float64, widths (len(lines),) int64).

    One C parse of all lines joined with a 'nan' sentinel between them gives each line's width without
    a Python loop; a line that itself holds 'nan' (or 'inf') is counted by splitting instead.
    Raises InvalidMeshError naming `what` when a token is not a number.
    """
    return _ragged(lines, what, b" nan ", np.float64)


def indices(lines: list[bytes], what: str) -> tuple[np.ndarray, np.ndarray]:
    """Like numbers() for lines of 1-based indices -> int64 values; '0' (never a valid index) is the
    sentinel, and ints parse faster than floats."""
    return _ragged(lines, what, b" 0 ", np.int64)


def _ragged(lines: list[bytes], what: str, sentinel: bytes, dtype: type) -> tuple[np.ndarray, np.ndarray]:
    if not lines:
        return np.zeros(0, dtype=dtype), np.zeros(0, dtype=np.int64)
    values = _fromstring(sentinel.join(lines), what, dtype)
    is_mark = np.isnan(values) if dtype is np.float64 else values == 0
    marks = np.flatnonzero(is_mark)
    if marks.size == len(lines) - 1:
        bounds = np.concatenate([[-1], marks, [values.size]])
        widths = np.diff(bounds) - 1
        return np.delete(values, marks), widths.astype(np.int64)
    widths = np.fromiter((len(line.split()) for line in lines), dtype=np.int64, count=len(lines))
    values = _fromstring(b" ".join(lines), what, dtype)
    if values.size != widths.sum():
        raise InvalidMeshError(f"{what} holds something that is not a number")
    return values, widths


def _fromstring(text: bytes, what: str, dtype: type = np.float64) -> np.ndarray:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)  # a partial parse warns: make it fail
            return np.fromstring(text, dtype=dtype, sep=" ")
    except (ValueError, DeprecationWarning):
        raise InvalidMeshError(f"{what} holds something that is not a number") from None


def first_columns(values: np.ndarray, widths: np.ndarray, k: int, what: str) -> np.ndarray:
    """The first k values of each row of a ragged table -> (rows, k); every row needs at least k."""
    if widths.size and widths.min() < k:
        raise InvalidMeshError(f"{what} has fewer than {k} numbers")
    if widths.size and (widths == k).all():
        return values.reshape(-1, k)
    starts = np.cumsum(widths) - widths
    return values[starts[:, None] + np.arange(k)]


def fan_triangulate(indices: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Polygons as a flat index list + sizes -> (sum(w - 2), 3) triangles (a fan from each first corner).

    indices : (sum w,) int64, widths : (p,) int64 with every w >= 3.
    """
    if widths.size and widths.min() < 3:
        raise InvalidMeshError("a face has fewer than 3 corners")
    if (widths == 3).all():
        return indices.reshape(-1, 3)
    starts = np.cumsum(widths) - widths  # (p,)
    per = widths - 2  # triangles per polygon
    poly = np.repeat(np.arange(widths.size), per)  # (t,)
    k = np.arange(poly.size) - np.repeat(np.cumsum(per) - per, per) + 1  # 1 .. w-2 within each polygon
    first = starts[poly]
    return np.stack([indices[first], indices[first + k], indices[first + k + 1]], axis=1)


def whole_numbers(values: np.ndarray, what: str) -> np.ndarray:
    """float64 values that must be integers (face indices) -> int64."""
    if values.size and (not np.isfinite(values).all() or (values != np.round(values)).any()):
        raise InvalidMeshError(f"{what} is not a whole number")
    if values.size and np.abs(values).max() > 2**53:
        raise InvalidMeshError(f"{what} is far out of range")
    return values.astype(np.int64)
