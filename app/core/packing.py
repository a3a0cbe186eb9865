"""Lossless packing of float32 tables for storage: what deflate cannot see in raw floats.

A description's HKS table, (n vertices, m time scales) float32, deflates poorly as it is (358 kB of
400 kB): each value's low mantissa bytes look random. Along the time axis the values change slowly, so
the difference of neighbouring bit patterns is small, and split into byte planes (all first bytes, then
all second bytes ...) the high planes are nearly constant: the same table deflates to ~207 kB, and
unpacks to the very same bits.
"""

from __future__ import annotations

import numpy as np


def pack_float32(table: np.ndarray) -> np.ndarray:
    """(..., m) float32 -> (4, size) uint8: bit-pattern differences along the last axis, as byte planes."""
    bits = np.ascontiguousarray(table, dtype="<f4").view("<u4")
    delta = np.diff(bits, axis=-1, prepend=np.zeros(bits.shape[:-1] + (1,), dtype="<u4"))  # mod 2**32
    return np.ascontiguousarray(delta.reshape(-1).view(np.uint8).reshape(-1, 4).T)


def unpack_float32(planes: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """pack_float32's inverse: (4, size) uint8 -> `shape` float32, bit for bit."""
    if planes.shape != (4, int(np.prod(shape))):
        raise ValueError(f"packed planes {planes.shape} do not hold a {shape} table")
    delta = np.ascontiguousarray(planes.T).reshape(-1).view("<u4").reshape(shape)
    return np.cumsum(delta, axis=-1, dtype="<u4").view("<f4").astype(np.float32)
