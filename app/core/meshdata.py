"""The mesh value, the errors a reader raises, and the size budget readers check before allocating.

Kept apart from mesh.py so that the readers (app/core/formats) and cleaning can import them without a cycle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MIN_VERTICES = 4
MIN_FACES = 4
# A flat-shaded export stores 3 vertices per triangle, about 6 per vertex of the welded mesh; a closed
# surface has about 2 faces per vertex, 8 leaves room for slivers and fans. Past these, no welding can
# bring the mesh under the vertex limit, so the file is refused before its arrays are allocated.
RAW_VERTEX_FACTOR = 6
FACE_FACTOR = 8


class InvalidMeshError(ValueError):
    """The input cannot be used as a triangle mesh; the message says why, in a user's words."""


class UnsupportedFormatError(InvalidMeshError):
    """The file is in a format (or a variant of one) that shapebag does not read; the message says
    which, and what to convert it to. The API answers 415."""


@dataclass(frozen=True)
class Mesh:
    """An indexed triangle mesh.

    vertices : (n, 3) float64
    faces    : (f, 3) int64, indices into vertices
    """

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def face_areas(self) -> np.ndarray:
        """(f,) float64 triangle areas."""
        v = self.vertices[self.faces]
        return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)

    def area(self) -> float:
        return float(self.face_areas().sum())


@dataclass(frozen=True)
class Budget:
    """What a reader may allocate, from the vertex limit (None: no limit, only consistency checks).

    Readers call these with the counts a file *declares*, before reading the arrays, so that a small
    file claiming billions of elements is refused without allocating them.
    """

    max_vertices: int | None = None

    def vertices(self, count: int, what: str) -> None:
        if count < 0:
            raise InvalidMeshError(f"the file is corrupt: {what} declares a negative count")
        if self.max_vertices is not None and count > RAW_VERTEX_FACTOR * self.max_vertices:
            raise InvalidMeshError(
                f"{what} declares {count} vertices: far more than the limit of {self.max_vertices}"
                " vertices could hold even after welding duplicates"
            )

    def faces(self, count: int, what: str) -> None:
        if count < 0:
            raise InvalidMeshError(f"the file is corrupt: {what} declares a negative count")
        if self.max_vertices is not None and count > FACE_FACTOR * self.max_vertices:
            raise InvalidMeshError(
                f"{what} declares {count} faces: far more than a mesh within the limit of"
                f" {self.max_vertices} vertices can have"
            )

    def unpacked_bytes(self) -> int:
        """Cap on the bytes a container (.zip, .3mf) may unpack to: ~256 bytes per allowed vertex."""
        return 1 << 40 if self.max_vertices is None else max(64 << 20, 256 * self.max_vertices)
