"""Variant relations for a query that is not stored (POST /search): the query's fingerprints, a lookup
among the stored ones, a geometric verification of the few candidates that are also search hits, all
inside the query pool's deadline. Advisory: any failure or lack of time leaves the hits without a
relation, never fails the search."""

from __future__ import annotations

import asyncio
import logging
import time
from pathlib import Path

import numpy as np

from app.core.mesh import InvalidMeshError, load_mesh
from app.core.variants import Prepared, relate
from app.core.variants.collection import fingerprints
from app.services import variants
from app.services.clients import ClientOverBudget
from app.services.context import ServiceContext
from app.services.errors import ServiceError
from app.services.query_pool import QueryDescriber
from app.storage import models as models_repo

log = logging.getLogger(__name__)
MIN_SECONDS = 0.5  # left of the deadline below which the step is not started
VERIFY_SHARE = 0.8  # of the time left given to verification; the rest covers loading and the return


def query_fingerprints(data: bytes, file_type: str, max_vertices: int) -> np.ndarray:
    """Pool process: the query mesh's fingerprints, (1 + objects, DIM) float32, as an ingest makes them."""
    return fingerprints(Prepared(load_mesh(data, file_type, max_vertices=max_vertices)))


def relate_query(
    data: bytes, file_type: str, max_vertices: int, stored: list[tuple[int, str, str]], budget_s: float
) -> dict[int, dict]:
    """Pool process: {model id: evidence} for the stored meshes (id, path, format) the query is more
    than `similar` to, nearest candidates first; no new candidate is started past budget_s."""
    t = time.perf_counter()
    query = Prepared(load_mesh(data, file_type, max_vertices=max_vertices))
    found: dict[int, dict] = {}
    for model_id, path, stored_type in stored:
        if time.perf_counter() - t > budget_s:
            break
        try:
            other = Prepared(load_mesh(Path(path).read_bytes(), stored_type, max_vertices=max_vertices))
        except (InvalidMeshError, OSError):
            continue  # gone or unreadable: no evidence
        evidence = relate(query, other)
        if evidence.relation != "similar":
            found[model_id] = evidence.to_dict()
    return found


async def relations(
    ctx: ServiceContext, describer: QueryDescriber, data: bytes, file_type: str, hit_ids: list[int],
    deadline: float,
) -> dict[int, dict]:
    """{hit model id: evidence of its relation to the query} for the hits that are verified variants.
    deadline: time.monotonic() by which the answer must be there (the query pool's)."""
    if not hit_ids or deadline - time.monotonic() < MIN_SECONDS:
        return {}
    max_vertices = ctx.settings.max_vertices
    try:
        vectors = await describer.run(query_fingerprints, (data, file_type, max_vertices),
                                      "fingerprinting the query mesh", timeout_s=deadline - time.monotonic())
        hits = set(hit_ids)
        candidates = [i for i in await asyncio.to_thread(variants.lookup, ctx, vectors) if i in hits]
        if not candidates:
            return {}
        stored = await asyncio.to_thread(_stored, ctx, candidates)
        left = deadline - time.monotonic()
        if not stored or left < MIN_SECONDS:
            return {}
        args = (data, file_type, max_vertices, stored, VERIFY_SHARE * left)
        return dict(await describer.run(relate_query, args, "checking the query's variants", timeout_s=left))
    except (ServiceError, ClientOverBudget, InvalidMeshError, MemoryError) as exc:  # advisory only
        log.info("variant relations for a query skipped: %s", exc)
        return {}


def _stored(ctx: ServiceContext, ids: list[int]) -> list[tuple[int, str, str]]:
    """(id, local path of its file, format) of the candidates still stored and not failed, in order."""
    with ctx.db.read() as conn:
        records = models_repo.get_many(conn, ids)
    out = []
    for i in ids:
        rec = records.get(i)
        if rec is not None and rec.status != "failed":
            out.append((i, str(ctx.blobs.mesh_path(rec.sha256, rec.file_type)), rec.file_type))
    return out
