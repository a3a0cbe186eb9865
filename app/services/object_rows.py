"""Object rows in the service: a multi-object file's distinct objects described at ingest (their
descriptions kept beside the model's), encoded with every vocabulary version the model is encoded
with, and searched beside the whole rows (LiveIndex.search_objects; merged in services/search.py)."""

from __future__ import annotations

import logging
import sqlite3
import time
from dataclasses import dataclass

import numpy as np

from app.core.mesh import InvalidMeshError, Mesh
from app.core.object_rows import ObjectRow, distinct_objects
from app.core.pipeline import DescribeParams, ShapeDescription, describe
from app.core.vocabulary import EncodeParams, Vocabulary
from app.services.context import ServiceContext
from app.storage import models as models_repo
from app.storage import objects as objects_repo

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DescribedObject:
    row: ObjectRow
    description: ShapeDescription


def describe_objects(mesh: Mesh, params: DescribeParams, max_rows: int,
                     budget_s: float = float("inf")) -> list[DescribedObject]:
    """The distinct objects of `mesh` (none for a single-object mesh, or max_rows 0), each described
    as a mesh of its own, largest first. An object that cannot be described (too small a spectrum) is
    left out: the file keeps its whole row and its other objects'. No object is started past
    `budget_s` seconds (the ingest's share for them: object rows never cost a file its ingest)."""
    if max_rows <= 0:
        return []
    start = time.monotonic()
    found = []
    for row in distinct_objects(mesh, max_rows):
        if time.monotonic() - start > budget_s:
            log.warning("object rows cut at %d: their describes took over %.0f s", row.part - 1, budget_s)
            break
        try:
            found.append(DescribedObject(row, describe(row.mesh, params)))
        except (InvalidMeshError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            log.info("object %d (%d faces) left without a row: %s", row.part, row.mesh.n_faces, exc)
    return found


def save_descriptions(ctx: ServiceContext, model_id: int, found: list[DescribedObject]) -> None:
    """Each object's description beside the model's (blobs: descriptions/<id>.o<part>.npz)."""
    for obj in found:
        ctx.blobs.put_description(model_id, obj.description.save, part=obj.row.part)


def store(conn: sqlite3.Connection, model_id: int, found: list[DescribedObject], vocabulary_id: int | None,
          vectors: list[np.ndarray] | None) -> None:
    """Register the objects (replacing an earlier ingest's) and their vectors under `vocabulary_id`."""
    objects_repo.put_objects(conn, model_id, [(o.row.part, o.row.copies, o.row.share) for o in found])
    if vocabulary_id is not None and vectors is not None:
        objects_repo.delete_vectors(conn, model_id, vocabulary_id)
        for obj, vec in zip(found, vectors, strict=True):
            objects_repo.put_vector(conn, model_id, obj.row.part, vocabulary_id, vec)


def encode_parts(ctx: ServiceContext, vocab: Vocabulary, params: EncodeParams,
                 parts: list[tuple[int, int]]) -> list[tuple[int, int, np.ndarray]]:
    """(model id, part, vector) of the object rows `parts` whose description is at hand."""
    out = []
    for model_id, part in parts:
        path = ctx.blobs.description_path(model_id, part)
        if not path.is_file():
            log.warning("object %d of model %d has no description: no row until it is ingested again",
                        part, model_id)
            continue
        out.append((model_id, part, vocab.encode(ShapeDescription.load(path), params)))
    return out


def store_vectors(conn: sqlite3.Connection, vocabulary_id: int,
                  rows: list[tuple[int, int, np.ndarray]]) -> None:
    """Store object rows' vectors of models still alive (deleted meanwhile: skipped)."""
    alive = set(models_repo.get_many(conn, sorted({m for m, _, _ in rows})))
    for model_id, part, vec in rows:
        if model_id in alive:
            objects_repo.put_vector(conn, model_id, part, vocabulary_id, vec)

