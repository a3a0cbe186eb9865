"""The objects of a multi-object file that get index rows of their own (issue 33, docs/partial.md).

A print plate or an assembly exported as one file is described as one disconnected surface, and its
vector is no object's: a query that is one of its objects never finds it. So each *distinct* object of
such a file is described as a mesh of its own and indexed as a row of the file too (a model's distance
is the least over its rows). The split is the variants' (app.core.variants.surface.objects: connected
components whose boxes overlap are one object); copies of one part (the same fingerprint) share one row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.core.meshdata import Mesh
from app.core.variants.fingerprint import fingerprint
from app.core.variants.surface import objects

MAX_ROWS = 8  # distinct objects a file gets rows for, the largest first
MIN_AREA_SHARE = 0.02  # of the largest object's area: smaller ones are trim, not parts (as the variants)
COPY_RADIUS = 0.05  # fingerprint L2 distance under which two objects are copies (variants.collection.SURE)
MIN_FACES = 4  # fewer faces is trim (a flat quad is 2), as clean() refuses a mesh of fewer
SPLIT_CAP = 128  # objects split off before copies are merged (the largest): a plate's many copies of one
# part must not crowd its other parts out


@dataclass(frozen=True)
class ObjectRow:
    """One distinct object of a file.

    part   : 1 = the largest distinct object, 2 = the next...
    mesh   : the object as it lies in the file
    copies : how many objects of the file are copies of it (itself included)
    share  : its area (one copy) over the file's total area, in (0, 1]
    """

    part: int
    mesh: Mesh
    copies: int
    share: float


def distinct_objects(mesh: Mesh, max_rows: int = MAX_ROWS) -> list[ObjectRow]:
    """The rows a file gets beside its whole: [] for a single-object mesh (its whole row is the object).

    Copies are told apart by the variants' fingerprint (scale- and motion-free, so a part and its
    rescaled copy share a row: the BoF is scale-free too)."""
    found = objects(mesh, MIN_AREA_SHARE, max_objects=SPLIT_CAP, min_faces=MIN_FACES)
    if len(found) < 2:
        return []
    total = float(mesh.face_areas().sum())
    prints = np.stack([fingerprint(o) for o in found])  # (n, 17)
    rows: list[ObjectRow] = []
    counts: list[int] = []
    owners: list[int] = []  # index into found of each row's representative
    for i in range(len(found)):  # largest first: a copy joins the first row it is close to
        near = [r for r, j in enumerate(owners) if np.linalg.norm(prints[i] - prints[j]) < COPY_RADIUS]
        if near:
            counts[near[0]] += 1
        else:
            owners.append(i)
            counts.append(1)
    for r, i in enumerate(owners[:max_rows]):
        share = float(found[i].face_areas().sum()) / total if total > 0 else 0.0
        rows.append(ObjectRow(r + 1, found[i], counts[r], share))
    return rows


def merge_rows(
    whole_dist: np.ndarray, whole_ids: np.ndarray,
    object_dist: np.ndarray, object_models: np.ndarray, object_parts: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One entry per model, its least distance over its rows, ascending (ties by model id, then the
    whole row first).

    whole_dist, whole_ids (n,); object_dist, object_models, object_parts (m,) ->
    distances (p,) float32, model ids (p,) int64, parts (p,) int64 (0: the whole row matched).
    """
    dist = np.concatenate([np.asarray(whole_dist, np.float64), np.asarray(object_dist, np.float64)])
    ids = np.concatenate([np.asarray(whole_ids, np.int64), np.asarray(object_models, np.int64)])
    parts = np.concatenate([np.zeros(len(whole_ids), np.int64), np.asarray(object_parts, np.int64)])
    order = np.lexsort((parts, ids, dist))  # by distance, then id, then part
    _, first = np.unique(ids[order], return_index=True)  # each model's first (nearest) entry
    sel = order[np.sort(first)]
    return dist[sel].astype(np.float32), ids[sel], parts[sel]
