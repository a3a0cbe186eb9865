"""Ingestion: accept an upload (dedup by content hash, queue a job) and run the job in a worker."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

from app.core.mesh import Mesh, detect_format, load_mesh
from app.core.pipeline import DescribeParams, ShapeDescription, canonical_with_rim, describe_canonical
from app.services import object_rows, variants, views
from app.services.clients import current_client
from app.services.context import ServiceContext
from app.services.errors import InvalidInputError, QueueFullError
from app.services.metadata import check_metadata
from app.services.vocabularies import load_vocabulary, version_params
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.storage.blobs import sha256_hex
from app.storage.jobs import JobRecord
from app.storage.models import ModelRecord

log = logging.getLogger(__name__)
OBJECTS_SHARE = 0.25  # of ingest_timeout_s that a file's object rows may take before the rest are left out


@dataclass(frozen=True)
class Submitted:
    model: ModelRecord
    job_id: int | None  # None: identical content was already there, no new work
    created: bool  # a new model (False: an existing one, re-queued if job_id is set)


def submit(
    ctx: ServiceContext,
    data: bytes,
    filename: str,
    name: str | None = None,
    label: str | None = None,
    metadata: dict | None = None,
) -> Submitted:
    """Store the mesh (content-addressed) and queue its ingest job; identical content -> existing model
    (a failed one is queued again: the failure may have been transient).

    The format is checked here (cheap); the geometry is checked by the worker, and a bad mesh fails
    its job with the reason.
    """
    file_type = detect_format(filename)  # UnsupportedFormatError: the same refusal as on /search
    if not data:
        raise InvalidInputError("the file is empty")
    metadata = check_metadata(metadata or {})  # a row that could not serialise back must never be stored
    digest = sha256_hex(data)
    ctx.blobs.put_mesh(data, file_type)  # outside the lock (the slow part); ensure_mesh re-checks under it
    with ctx.db.write() as conn:
        existing = models_repo.get_by_sha256(conn, digest)
        if existing is not None and existing.status != "failed":
            return Submitted(existing, None, False)  # identical content: the existing model
        if jobs_repo.queue_depth(conn)["queued"] >= ctx.settings.queue_limit:
            if existing is None:
                ctx.blobs.mesh_path(digest, file_type).unlink(missing_ok=True)  # no model refers to it
            raise QueueFullError(
                f"the ingestion queue is full ({ctx.settings.queue_limit} jobs): retry later"
            )
        # a delete of the same content may have removed the file since put_mesh: deletes remove files
        # under this lock, so checking here is enough (see catalog.delete_model)
        if existing is not None:  # a failed model: uploading its bytes again retries it
            if existing.file_type != file_type:  # same bytes, another extension: keep the model's file
                ctx.blobs.mesh_path(digest, file_type).unlink(missing_ok=True)
            ctx.blobs.ensure_mesh(data, digest, existing.file_type, conn)
            models_repo.set_queued(conn, existing.id)
            job_id = jobs_repo.enqueue(conn, "ingest", model_id=existing.id, client=current_client())
            model = models_repo.get(conn, existing.id)
            assert model is not None
            return Submitted(model, job_id, False)
        ctx.blobs.ensure_mesh(data, digest, file_type, conn)
        model_id = models_repo.insert(
            conn,
            name=name or Path(filename).stem,
            label=label or None,
            metadata=metadata,
            sha256=digest,
            file_type=file_type,
            size_bytes=len(data),
        )
        job_id = jobs_repo.enqueue(conn, "ingest", model_id=model_id, client=current_client())
        model = models_repo.get(conn, model_id)
    assert model is not None
    return Submitted(model, job_id, True)


def describe_and_view(mesh: Mesh, params: DescribeParams) -> tuple[ShapeDescription, Mesh]:
    """describe(mesh, params) and the canonical mesh it was made on (the explain view's), resampled once.
    The rim (free boundary, and the caps that closed small holes) is describe()'s, so a stored model's
    local signature and rim are those of the same mesh described as a query."""
    t = time.perf_counter()
    fine, rim = canonical_with_rim(mesh, params)
    canonical_s = time.perf_counter() - t
    description = describe_canonical(mesh, fine, rim, params)
    description.seconds["resample"] = description.seconds.get("resample", 0.0) + canonical_s
    return description, fine


def run_ingest(ctx: ServiceContext, job: JobRecord) -> dict:
    """Describe the model's mesh, cache the description, encode with the active vocabulary, mark ready.

    Raises InvalidMeshError for a mesh that can never be described (the worker fails the job at once).
    """
    timings: dict[str, float] = {}
    t = time.perf_counter()
    with ctx.db.read() as conn:
        model = models_repo.get(conn, job.model_id) if job.model_id is not None else None
    if model is None:
        with ctx.db.write() as conn:
            jobs_repo.mark_done(conn, job.id, {"note": "model was deleted before ingestion"})
        return timings
    data = ctx.blobs.mesh_path(model.sha256, model.file_type).read_bytes()
    mesh = load_mesh(data, model.file_type, max_vertices=ctx.settings.max_vertices)
    timings["load"] = time.perf_counter() - t
    params = ctx.settings.describe.params()
    description, fine = describe_and_view(mesh, params)
    timings.update({f"describe.{k}": v for k, v in description.seconds.items()})
    t = time.perf_counter()
    # a plate's objects, within a quarter of the job's wall clock (they never fail the ingest)
    parts = object_rows.describe_objects(mesh, params, ctx.settings.object_rows,
                                         budget_s=OBJECTS_SHARE * ctx.settings.ingest_timeout_s)
    object_rows.save_descriptions(ctx, model.id, parts)
    timings["objects"] = time.perf_counter() - t
    found, timings["variants"] = variants.timed_detect(ctx, model.id, mesh)  # advisory: never fails a job
    ctx.blobs.put_description(model.id, description.save)
    views.save_geometry(ctx, model.id, fine)  # what /explain shows, kept now rather than per view
    views.save_thumbnail(ctx, model.id, mesh)  # what a results page shows first, likewise
    for _ in range(5):  # encode with the active version; redo if a swap lands meanwhile
        t = time.perf_counter()
        with ctx.db.read() as conn:
            active = vocab_repo.active(conn)
        vector, part_vectors = None, None
        if active is not None:
            vocab = load_vocabulary(ctx, active)
            encoding = version_params(ctx, active, vocab)
            vector = vocab.encode(description, encoding)
            part_vectors = [vocab.encode(p.description, encoding) for p in parts]
        timings["encode"] = time.perf_counter() - t
        with ctx.db.write() as conn:
            now_active = vocab_repo.active(conn)
            if (now_active.id if now_active else None) != (active.id if active else None):
                continue
            if models_repo.get(conn, model.id) is None:
                jobs_repo.mark_done(conn, job.id, dict(timings, note="model deleted during ingestion"))
                ctx.blobs.delete_model_files(model.id, conn=conn)  # the description, written after the delete
                return timings
            if active is not None and vector is not None:
                vocab_repo.put_vector(conn, model.id, active.id, vector)
            object_rows.store(conn, model.id, parts, None if active is None else active.id, part_vectors)
            models_repo.set_ready(conn, model.id, mesh.n_vertices)
            result = {"variants": found, "object_rows": len(parts)}
            jobs_repo.mark_done(conn, job.id, {**timings, "result": result})
        return timings
    raise RuntimeError("the active vocabulary kept changing during ingestion")
