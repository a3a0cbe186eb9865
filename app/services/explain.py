"""Why it matched: a model's (or an uploaded query's) words per vertex, keypoints and BoF, beside another's.

The numbers come from app.core.explain; this module joins them with storage: the cached description
(.npz, no eigen-solve again), the active vocabulary of the live index, and the canonical-resolution
geometry the words live on. That geometry is kept at ingest (services/views.py); for a model ingested
before, it is recomputed once from the stored mesh by the same resolution policy as describe()
(decimation and subdivision are deterministic), in a query-pool process: the API process never decodes
a mesh. The vertex counts are compared, so a description made under other
settings is refused rather than coloured wrongly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core.explain import ShapeWords, contributions, shape_words, top_words
from app.core.mesh import Mesh, load_mesh
from app.core.pipeline import (
    DescribeParams,
    ShapeDescription,
    canonical_mesh,
    canonical_with_rim,
    describe_canonical,
)
from app.core.vocabulary import EncodeParams, Vocabulary
from app.services.context import ServiceContext
from app.services.errors import ConflictError, InvalidInputError, NotFoundError
from app.services.mesh_policy import load_upload
from app.services.thumbnail_view import canonical_rotation
from app.storage.models import ModelRecord

TOP_WORDS = 8


@dataclass(frozen=True)
class Geometry:
    vertices: np.ndarray  # (n, 3) float32, canonical resolution, centred, in the thumbnail's view frame
    faces: np.ndarray  # (f, 3) int32


@dataclass(frozen=True)
class Side:
    """One shape of an explanation: who it is, its geometry, its words."""

    model_id: int | None  # None: an uploaded query
    name: str
    label: str | None
    geometry: Geometry
    seen: ShapeWords


@dataclass(frozen=True)
class Explanation:
    vocabulary_id: int
    size: int  # words in the vocabulary
    shape: Side
    against: Side | None
    terms: np.ndarray | None  # (v,) |a_i - b_i| per word
    top: np.ndarray | None  # word ids, largest term first
    distance: float | None  # the distance the index ranks by (BoF, fused with Shape-DNA when so encoded)


# ---- run in a query-pool process ------------------------------------------------------------------------


def _canonical(mesh: Mesh, params: DescribeParams) -> Geometry:
    return from_canonical(canonical_mesh(mesh, params))


def from_canonical(fine: Mesh) -> Geometry:
    """The explain view of canonical_mesh(mesh, params): kept at ingest (services/views.py)."""
    # centred and turned as the thumbnails are (upright, largest silhouette facing the camera): a viewer
    # opens on the same picture as the card it came from
    v = fine.vertices.astype(np.float64)
    v = (v - v.mean(axis=0)) @ canonical_rotation(v, fine.faces).T
    return Geometry(v.astype(np.float32), fine.faces.astype(np.int32))


def stored_geometry(path: str, file_type: str, params: DescribeParams, max_vertices: int) -> Geometry:
    """A stored mesh at the canonical resolution, loaded as ingestion loads it."""
    try:
        mesh = load_mesh(Path(path).read_bytes(), file_type, max_vertices=max_vertices)
    except FileNotFoundError:  # deleted meanwhile
        raise NotFoundError("the model's mesh is gone") from None
    return _canonical(mesh, params)


def query_geometry(
    data: bytes, file_type: str, params: DescribeParams, max_vertices: int
) -> tuple[ShapeDescription, Geometry]:
    """An uploaded query: its description and its canonical geometry (one load, as /search loads it)."""
    mesh = load_upload(data, file_type, max_vertices)
    fine, rim = canonical_with_rim(mesh, params)
    return describe_canonical(mesh, fine, rim, params), from_canonical(fine)


# ---- in the API process (threads) -------------------------------------------------------------------------


def stored_description(ctx: ServiceContext, model: ModelRecord) -> ShapeDescription:
    if model.status != "ready":
        raise ConflictError(f"model {model.id} is {model.status}: it has no description to explain yet")
    path = ctx.blobs.description_path(model.id)
    if not path.is_file():
        raise NotFoundError(f"model {model.id} has no cached description")
    return ShapeDescription.load(path)


def side(
    model: ModelRecord | None,
    name: str,
    description: ShapeDescription,
    geometry: Geometry,
    vocabulary: Vocabulary,
    params: EncodeParams,
) -> Side:
    if len(geometry.vertices) != description.n_vertices:
        raise InvalidInputError(
            f"{name}: its description has {description.n_vertices} vertices but the mesh resamples to "
            f"{len(geometry.vertices)} under the current settings: re-ingest it to explain it"
        )
    return Side(
        model_id=model.id if model else None,
        name=name,
        label=model.label if model else None,
        geometry=geometry,
        seen=shape_words(description, vocabulary, params),
    )


def explain(vocabulary_id: int, vocabulary: Vocabulary, shape: Side, against: Side | None) -> Explanation:
    if against is None:
        return Explanation(vocabulary_id, vocabulary.size, shape, None, None, None, None)
    terms = contributions(shape.seen.bof, against.seen.bof)
    distance = float(np.abs(shape.seen.vector.astype(np.float64) - against.seen.vector).sum())
    return Explanation(
        vocabulary_id, vocabulary.size, shape, against, terms, top_words(terms, TOP_WORDS), distance
    )
