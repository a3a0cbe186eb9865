"""ingestion.submit and ingestion.run_ingest called in-process (their other tests run
workers in subprocesses). What an upload stores (the model row, its mesh
file, one queued job), what identical content does (the same model; a failed one queued again), the
refusals (format, empty, metadata, a full queue) and what they leave behind; what an ingest job stores
(description, vector under the active vocabulary, ready with its vertex count, job done with timings),
deleted models before and during the job, and a vocabulary swap while it encodes."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.core.meshdata import InvalidMeshError, UnsupportedFormatError
from app.services import ingestion
from app.services.context import open_context
from app.services.errors import InvalidInputError, QueueFullError
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.storage.blobs import sha256_hex

# a tetrahedron: 4 vertices, 4 faces (a valid closed mesh the real loader accepts)
TETRA = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
OTHER = TETRA + b"# another file, the same shape\n"


@pytest.fixture
def ctx(settings):
    return open_context(settings)


def _model(ctx, model_id):
    with ctx.db.read() as conn:
        return models_repo.get(conn, model_id)


def _job(ctx, job_id):
    with ctx.db.read() as conn:
        return jobs_repo.get(conn, job_id)


def _jobs(ctx):
    with ctx.db.read() as conn:
        return conn.execute("SELECT id, kind, state, model_id FROM jobs ORDER BY id").fetchall()


def _mesh_files(ctx):
    return sorted(p.name for p in (ctx.data_dir / "meshes").rglob("*") if p.is_file())


def _fail(ctx, model_id):
    with ctx.db.write() as conn:
        models_repo.set_failed(conn, model_id, "boom")
        conn.execute("UPDATE jobs SET state = 'failed' WHERE model_id = ?", (model_id,))


# --- submit -----------------------------------------------------------------------------------------


def test_a_new_upload_stores_the_model_its_mesh_and_one_queued_job(ctx):
    s = ingestion.submit(ctx, TETRA, "dir/Chair-01.obj", label="chair", metadata={"src": "x"})
    assert s.created is True and s.job_id is not None
    digest = sha256_hex(TETRA)
    m = _model(ctx, s.model.id)
    assert m == s.model
    assert (m.name, m.label, m.metadata, m.sha256, m.file_type, m.size_bytes, m.status) == (
        "Chair-01",  # the file name's stem when no name is given
        "chair",
        {"src": "x"},
        digest,
        "obj",
        len(TETRA),
        "queued",
    )
    assert ctx.blobs.mesh_path(digest, "obj").read_bytes() == TETRA
    assert [tuple(r) for r in _jobs(ctx)] == [(s.job_id, "ingest", "queued", m.id)]


def test_a_given_name_wins_and_an_empty_label_is_none(ctx):
    s = ingestion.submit(ctx, TETRA, "x.OBJ", name="my chair", label="")
    assert (s.model.name, s.model.label, s.model.metadata, s.model.file_type) == ("my chair", None, {}, "obj")


@pytest.mark.parametrize(
    ("data", "filename", "metadata", "error", "message"),
    [
        (TETRA, "chair.docx", None, UnsupportedFormatError, "docx"),
        (b"", "chair.obj", None, InvalidInputError, "^the file is empty$"),
        (TETRA, "chair.obj", {"x": float("nan")}, InvalidInputError, "NaN"),
    ],
)
def test_a_refused_upload_stores_nothing(ctx, data, filename, metadata, error, message):
    with pytest.raises(error, match=message):
        ingestion.submit(ctx, data, filename, metadata=metadata)
    assert _jobs(ctx) == [] and _mesh_files(ctx) == []
    with ctx.db.read() as conn:
        assert conn.execute("SELECT COUNT(*) FROM models").fetchone()[0] == 0


def test_identical_content_is_the_existing_model_and_queues_nothing(ctx):
    first = ingestion.submit(ctx, TETRA, "a.obj", name="first")
    again = ingestion.submit(ctx, TETRA, "b.obj", name="second", label="other")
    assert again == ingestion.Submitted(first.model, None, False)
    assert len(_jobs(ctx)) == 1


def test_identical_content_of_a_failed_model_queues_it_again_with_its_own_file(ctx):
    first = ingestion.submit(ctx, TETRA, "a.obj")
    _fail(ctx, first.model.id)
    digest = sha256_hex(TETRA)
    ctx.blobs.mesh_path(digest, "obj").unlink()  # e.g. removed meanwhile: written again under the lock
    again = ingestion.submit(ctx, TETRA, "a.off")  # same bytes, another extension
    assert again.created is False and again.job_id not in (None, first.job_id)
    assert again.model.id == first.model.id
    assert (again.model.status, again.model.error, again.model.file_type) == ("queued", None, "obj")
    assert _model(ctx, first.model.id) == again.model
    assert _job(ctx, again.job_id).state == "queued" and _job(ctx, again.job_id).model_id == first.model.id
    assert _mesh_files(ctx) == [f"{digest}.obj"]  # the model's file is back, the .off copy is gone
    assert ctx.blobs.mesh_path(digest, "obj").read_bytes() == TETRA


def test_a_mesh_removed_after_put_mesh_is_written_again(ctx, monkeypatch):
    """A delete of the same content may remove the file between put_mesh and the lock."""
    _lose_the_put_file(ctx, monkeypatch)
    s = ingestion.submit(ctx, TETRA, "a.obj")
    assert ctx.blobs.mesh_path(s.model.sha256, "obj").read_bytes() == TETRA


def _queue(ctx, n):
    with ctx.db.write() as conn:
        for _ in range(n):
            jobs_repo.enqueue(conn, "ingest")


def test_a_full_queue_refuses_a_new_upload_and_removes_its_file(ctx):
    ctx = ingestion.ServiceContext(ctx.settings.model_copy(update={"queue_limit": 2}), ctx.db, ctx.blobs)
    _queue(ctx, 1)
    ingestion.submit(ctx, TETRA, "a.obj")  # the second queued job: the limit is reached, not passed
    with pytest.raises(QueueFullError, match=r"the ingestion queue is full \(2 jobs\): retry later"):
        ingestion.submit(ctx, OTHER, "b.obj")
    assert _mesh_files(ctx) == [f"{sha256_hex(TETRA)}.obj"]
    with ctx.db.read() as conn:
        assert models_repo.get_by_sha256(conn, sha256_hex(OTHER)) is None
    assert len(_jobs(ctx)) == 2


def test_running_jobs_do_not_fill_the_queue(ctx):
    ctx = ingestion.ServiceContext(ctx.settings.model_copy(update={"queue_limit": 1}), ctx.db, ctx.blobs)
    _queue(ctx, 1)
    with ctx.db.write() as conn:
        conn.execute("UPDATE jobs SET state = 'running'")
    assert ingestion.submit(ctx, TETRA, "a.obj").job_id is not None


def _lose_the_put_file(ctx, monkeypatch):
    """put_mesh writes the file, then a delete of the same content removes it (before the lock)."""
    put = ctx.blobs.put_mesh

    def put_then_lost(data, file_type):
        digest, path = put(data, file_type)
        path.unlink()
        return digest, path

    monkeypatch.setattr(ctx.blobs, "put_mesh", put_then_lost)


def test_a_full_queue_refuses_even_when_the_file_is_already_gone(ctx, monkeypatch):
    ctx = ingestion.ServiceContext(ctx.settings.model_copy(update={"queue_limit": 1}), ctx.db, ctx.blobs)
    _queue(ctx, 1)
    _lose_the_put_file(ctx, monkeypatch)
    with pytest.raises(QueueFullError):
        ingestion.submit(ctx, TETRA, "a.obj")


def test_a_failed_model_under_another_extension_when_that_file_is_already_gone(ctx, monkeypatch):
    first = ingestion.submit(ctx, TETRA, "a.obj")
    _fail(ctx, first.model.id)
    _lose_the_put_file(ctx, monkeypatch)
    again = ingestion.submit(ctx, TETRA, "a.off")
    assert again.job_id is not None and _mesh_files(ctx) == [f"{first.model.sha256}.obj"]


def test_a_failed_model_is_queued_again_on_the_database_blob_store(settings):
    """The mesh is stored inside the submit's own transaction (a second one would wait on it)."""
    ctx = open_context(settings.model_copy(update={"blob_backend": "database"}))
    first = ingestion.submit(ctx, TETRA, "a.obj")
    _fail(ctx, first.model.id)
    again = ingestion.submit(ctx, TETRA, "a.obj")
    assert again.job_id is not None and again.model.status == "queued"
    assert ctx.blobs.mesh_path(first.model.sha256, "obj").read_bytes() == TETRA


def test_a_full_queue_keeps_the_file_of_a_failed_model(ctx):
    first = ingestion.submit(ctx, TETRA, "a.obj")
    _fail(ctx, first.model.id)
    ctx = ingestion.ServiceContext(ctx.settings.model_copy(update={"queue_limit": 1}), ctx.db, ctx.blobs)
    _queue(ctx, 1)
    with pytest.raises(QueueFullError):
        ingestion.submit(ctx, TETRA, "a.obj")
    assert ctx.blobs.mesh_path(first.model.sha256, "obj").read_bytes() == TETRA
    assert _model(ctx, first.model.id).status == "failed"


# --- run_ingest ---------------------------------------------------------------------------------------


class FakeDescription:
    seconds = {"spectrum": 0.25, "hks": 0.5}

    def save(self, path):
        with open(path, "wb") as fh:
            fh.write(b"description")


@pytest.fixture
def fakes(ctx, monkeypatch):
    return _fakes(ctx, monkeypatch)


def _fakes(ctx, monkeypatch):
    """describe and the vocabulary replaced by recorders; `on_encode` runs inside each encode."""
    seen = SimpleNamespace(describe=[], encode=[], on_encode=lambda: None)

    def describe(mesh, params):
        seen.describe.append((mesh.n_vertices, params))
        return FakeDescription()

    class Vocab:
        def __init__(self, record):
            self.record = record
            self.metadata: dict = {}  # no fit encoding: the version's record (or the settings) decide

        def encode(self, description, params):
            seen.encode.append((self.record.id, type(description), params))
            seen.on_encode()
            return np.full(3, self.record.id, np.float32)

    monkeypatch.setattr(ingestion, "describe_and_view", lambda mesh, params: (describe(mesh, params), mesh))

    def load_vocabulary(c, record):
        assert c is ctx  # the versions live in this service's data directory
        return Vocab(record)

    monkeypatch.setattr(ingestion, "load_vocabulary", load_vocabulary)
    return seen


def _vocabulary(ctx, activate=True):
    with ctx.db.write() as conn:
        vid = vocab_repo.insert(conn, path="v", trained_on=1, size=3, run="r", metadata={})
        if activate:
            vocab_repo.activate(conn, vid)
    return vid


def _submitted_job(ctx, data=TETRA):
    s = ingestion.submit(ctx, data, "a.obj")
    return s.model.id, _job(ctx, s.job_id)


def test_an_ingest_describes_encodes_and_marks_the_model_ready(ctx, fakes):
    vid = _vocabulary(ctx)
    model_id, job = _submitted_job(ctx)
    timings = ingestion.run_ingest(ctx, job)
    assert set(timings) == {"load", "describe.spectrum", "describe.hks", "objects", "variants", "encode"}
    assert (timings["describe.spectrum"], timings["describe.hks"]) == (0.25, 0.5)
    assert all(0 <= v < 60 for v in timings.values())  # durations, not clock readings
    assert fakes.describe == [(4, ctx.settings.describe.params())]
    assert fakes.encode == [(vid, FakeDescription, ctx.settings.encode.params())]
    m = _model(ctx, model_id)
    assert (m.status, m.n_vertices) == ("ready", 4)
    assert ctx.blobs.description_path(model_id).read_bytes() == b"description"
    with ctx.db.read() as conn:
        assert vocab_repo.vector_of(conn, model_id, vid).tolist() == [vid] * 3
    done = _job(ctx, job.id)
    # the job's result names the likely variants (none: the model is alone)
    result = {"variants": [], "object_rows": 0}  # nor has it objects of its own (app.core.object_rows)
    assert (done.state, done.error, done.timings) == ("done", None, {**timings, "result": result})


def test_without_a_vocabulary_the_model_is_ready_without_a_vector(ctx, fakes):
    vid = _vocabulary(ctx, activate=False)
    model_id, job = _submitted_job(ctx)
    timings = ingestion.run_ingest(ctx, job)
    assert fakes.encode == [] and "encode" in timings
    assert _model(ctx, model_id).status == "ready"
    with ctx.db.read() as conn:
        assert vocab_repo.vector_of(conn, model_id, vid) is None
    assert _job(ctx, job.id).state == "done"


def test_a_mesh_over_the_vertex_limit_fails_in_words(ctx, fakes):
    ctx = ingestion.ServiceContext(ctx.settings.model_copy(update={"max_vertices": 3}), ctx.db, ctx.blobs)
    _, job = _submitted_job(ctx)
    with pytest.raises(InvalidMeshError, match="limit of 3"):
        ingestion.run_ingest(ctx, job)
    assert fakes.describe == []


@pytest.mark.parametrize("how", ["deleted", "no model"])
def test_a_model_deleted_before_its_job_is_done_with_a_note(ctx, fakes, how):
    model_id, job = _submitted_job(ctx)
    if how == "deleted":
        with ctx.db.write() as conn:
            models_repo.delete(conn, model_id)
    else:
        job = jobs_repo.JobRecord(**{**job.__dict__, "model_id": None})
    assert ingestion.run_ingest(ctx, job) == {}
    done = _job(ctx, job.id)
    assert (done.state, done.timings) == ("done", {"note": "model was deleted before ingestion"})
    assert fakes.describe == []


@pytest.mark.parametrize("blob_backend", ["filesystem", "database"])
def test_a_model_deleted_during_the_job_leaves_no_description(settings, monkeypatch, blob_backend):
    """The description written after the delete goes, inside the job's own write (the database store
    deletes its copy in that transaction: a second one would wait on SQLite's one writer)."""
    ctx = open_context(settings.model_copy(update={"blob_backend": blob_backend}))
    fakes = _fakes(ctx, monkeypatch)
    vid = _vocabulary(ctx)
    model_id, job = _submitted_job(ctx)

    def delete():
        with ctx.db.write() as conn:
            models_repo.delete(conn, model_id)

    fakes.on_encode = delete
    timings = ingestion.run_ingest(ctx, job)
    assert not ctx.blobs.description_path(model_id).exists()
    done = _job(ctx, job.id)
    assert (done.state, done.timings) == ("done", dict(timings, note="model deleted during ingestion"))
    assert set(timings) == {"load", "describe.spectrum", "describe.hks", "objects", "variants", "encode"}
    with ctx.db.read() as conn:
        assert vocab_repo.vector_of(conn, model_id, vid) is None


def test_a_vocabulary_swap_while_encoding_encodes_again_with_the_new_one(ctx, fakes):
    old = _vocabulary(ctx)
    new = _vocabulary(ctx, activate=False)

    def swap_once():
        if len(fakes.encode) == 1:
            with ctx.db.write() as conn:
                vocab_repo.activate(conn, new)

    fakes.on_encode = swap_once
    model_id, job = _submitted_job(ctx)
    ingestion.run_ingest(ctx, job)
    assert [e[0] for e in fakes.encode] == [old, new]
    with ctx.db.read() as conn:
        assert vocab_repo.vector_of(conn, model_id, old) is None
        assert vocab_repo.vector_of(conn, model_id, new).tolist() == [new] * 3
    assert _model(ctx, model_id).status == "ready" and _job(ctx, job.id).state == "done"


def test_a_vocabulary_activated_while_encoding_without_one_is_used(ctx, fakes, monkeypatch):
    """None active when the job read it, one active when it writes: encode again, with that one."""
    vid = _vocabulary(ctx, activate=False)
    model_id, job = _submitted_job(ctx)
    reads = []

    def active_then_activate(conn):
        record = vocab_repo.active(conn)
        reads.append(record.id if record else None)
        if len(reads) == 1:  # the job's read: a rebuild activates a version right after it
            with ctx.db.write() as other:
                vocab_repo.activate(other, vid)
        return record

    monkeypatch.setattr(
        ingestion,
        "vocab_repo",
        SimpleNamespace(active=active_then_activate, put_vector=vocab_repo.put_vector),
    )
    ingestion.run_ingest(ctx, job)
    assert reads == [None, vid, vid, vid] and [e[0] for e in fakes.encode] == [vid]
    with ctx.db.read() as conn:
        assert vocab_repo.vector_of(conn, model_id, vid).tolist() == [vid] * 3


def test_a_vocabulary_that_keeps_changing_gives_up_after_five_tries(ctx, fakes):
    a, b = _vocabulary(ctx), _vocabulary(ctx, activate=False)

    def swap():
        with ctx.db.write() as conn:
            vocab_repo.activate(conn, b if vocab_repo.active(conn).id == a else a)

    fakes.on_encode = swap
    model_id, job = _submitted_job(ctx)
    with pytest.raises(RuntimeError, match="^the active vocabulary kept changing during ingestion$"):
        ingestion.run_ingest(ctx, job)
    assert len(fakes.encode) == 5
    assert _model(ctx, model_id).status == "queued" and _job(ctx, job.id).state == "queued"


def test_a_stored_description_has_the_rim_of_the_same_mesh_described_as_a_query():
    """describe_and_view (ingest) resamples once for the explain view; its description must still be
    describe()'s, rim included: a small hole closed by a cap is a boundary for the local signature and
    the fusion re-rank (an open model). A sphere with a small hole at its pole: capped, rim > 0."""
    import trimesh

    from app.core.meshdata import Mesh
    from app.core.pipeline import DescribeParams, _rim_mask, canonical_mesh, describe, describe_canonical

    sphere = trimesh.creation.icosphere(subdivisions=4)
    keep = np.flatnonzero(np.linalg.norm(sphere.triangles_center - [0, 0, 1], axis=1) > 0.1)
    mesh = Mesh(np.asarray(sphere.vertices, np.float64), np.asarray(sphere.faces[keep], np.int64))
    params = DescribeParams(k=40, m=20, target_vertices=600)
    want = describe(mesh, params)
    got, fine = ingestion.describe_and_view(mesh, params)
    assert want.local is not None and got.local is not None
    assert want.local.rim > 0  # the cap's rim counts
    assert got.local.rim == pytest.approx(want.local.rim)
    np.testing.assert_array_equal(got.local.valid, want.local.valid)
    np.testing.assert_allclose(got.local.slopes, want.local.slopes, rtol=1e-5, atol=1e-6)
    assert fine.n_vertices == canonical_mesh(mesh, params).n_vertices
    # what the ingest stored before: the capped mesh described as if it were closed (its own open boundary)
    as_closed = _rim_mask(fine.faces, fine.n_vertices, fine.n_vertices)
    assert describe_canonical(mesh, fine, as_closed, params).local.rim == 0.0
    # the ingest records the noise of the mesh as given, as describe() does
    assert got.input_noise == pytest.approx(want.input_noise) and np.isfinite(got.input_noise)
