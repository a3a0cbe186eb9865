"""Raw Draco (.drc) through DracoPy."""

from __future__ import annotations

import numpy as np

from app.core.formats.scene import short
from app.core.meshdata import Budget, InvalidMeshError


def read_drc(data: bytes, budget: Budget) -> tuple[np.ndarray, np.ndarray]:
    """A raw Draco bitstream (what draco_encoder writes) -> vertices (n, 3), faces (f, 3)."""
    import DracoPy

    if not data.startswith(b"DRACO"):
        raise InvalidMeshError("could not read the file as Draco: it does not start with 'DRACO'")
    try:
        decoded = DracoPy.decode(data)
    except Exception as exc:  # the decoder raises its own types for corrupt streams
        raise InvalidMeshError(f"could not read the file as Draco: {short(exc)}") from exc
    points = np.asarray(decoded.points, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(getattr(decoded, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
    budget.vertices(len(points), "the Draco file")
    budget.faces(len(faces), "the Draco file")
    return points, faces
