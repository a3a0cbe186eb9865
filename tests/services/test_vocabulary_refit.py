"""The background refit of the vocabulary on the collection (services/refit.py): when it is queued,
that it runs once at a time, that a failed one leaves the old vocabulary serving, that searches answer
during it."""

from __future__ import annotations

import threading

import pytest
from fastapi.testclient import TestClient

from app.cli import main
from app.core.vocabulary import Vocabulary
from app.main import create_app
from app.services import catalog, ingestion, refit, search
from app.services import vocabularies as vocab_service
from app.services.context import ServiceContext, open_context
from app.services.live_index import LiveIndex
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.worker.runner import Worker
from tests.conftest import make_settings


@pytest.mark.parametrize(
    ("threshold", "fitted_on", "failed_at", "due"),
    [
        (0, 0, 0, None),  # off
        (0, 500, 0, None),  # off, whatever was fit before
        (200, 0, 0, 200),  # shipped vocabulary: first at the threshold
        (200, 200, 0, 400),  # then at each doubling of the last fit
        (200, 250, 0, 500),  # doubling of the size it was fit at, not of the threshold
        (200, 150, 0, 300),  # an admin rebuild at 150 counts: 300 is its doubling, past the threshold
        (200, 40, 0, 200),  # a first fit at 40 (AUTO_VOCABULARY_MIN_MODELS): the threshold comes first
        (200, 0, 230, 460),  # a refit that failed at 230 is tried again at 460, not at every ingest
        (200, 400, 230, 800),  # the larger of the last fit and the failed attempt
    ],
)
def test_the_refit_is_due_at_the_threshold_then_at_each_doubling(threshold, fitted_on, failed_at, due):
    assert refit.refit_due_at(threshold, fitted_on, failed_at) == due


def _ready(ctx: ServiceContext) -> int:
    with ctx.db.read() as conn:
        return models_repo.count_by_status(conn)["ready"]


def _rebuild_jobs(ctx: ServiceContext) -> list[jobs_repo.JobRecord]:
    with ctx.db.read() as conn:
        rows = conn.execute("SELECT id FROM jobs WHERE kind = 'rebuild_vocabulary' ORDER BY id").fetchall()
        return [jobs_repo.get(conn, r["id"]) for r in rows]  # type: ignore[misc]


def _active(ctx: ServiceContext) -> vocab_repo.VocabularyRecord:
    with ctx.db.read() as conn:
        record = vocab_repo.active(conn)
    assert record is not None
    return record


def _activate_a_foreign_vocabulary(ctx: ServiceContext) -> int:
    """Activate a copy of the active vocabulary registered as one fit elsewhere (like the shipped one)."""
    vocab = Vocabulary.load(ctx.data_dir / _active(ctx).path)
    return vocab_service.register(ctx, vocab, activate=True)


def _ingest(ctx: ServiceContext, worker: Worker, path, copy: int = 0) -> int:
    """Upload `path` (copy > 0: with that many trailing newlines, new content) and run its ingest job."""
    data = path.read_bytes() + b"\n" * copy
    sub = ingestion.submit(ctx, data, path.name, name=f"{path.stem}-{copy}")
    job = worker.run_once()
    assert job is not None and job.id == sub.job_id
    with ctx.db.read() as conn:
        assert jobs_repo.get(conn, sub.job_id).state == "done"  # type: ignore[union-attr]
    return sub.model.id


def test_a_refit_is_queued_at_the_threshold_and_at_its_doubling_not_before(data_dir, corpus):
    ctx = open_context(make_settings(data_dir, vocabulary_refit_at=6))
    assert _active(ctx).metadata["collection_models"] == 12  # the seeding rebuild fit on the collection
    with ctx.db.read() as conn:
        ids = models_repo.ready_ids(conn)
    for mid in ids[5:]:
        catalog.delete_model(ctx, None, mid)
    foreign = _activate_a_foreign_vocabulary(ctx)
    assert "collection_models" not in _active(ctx).metadata and _ready(ctx) == 5
    before = len(_rebuild_jobs(ctx))
    worker = Worker(ctx, "w")
    worker.run_forever(exit_when_idle=True)  # a starting worker checks too: 5 < 6
    assert len(_rebuild_jobs(ctx)) == before

    _ingest(ctx, worker, corpus.held_out[0][0])  # 6: due
    jobs = _rebuild_jobs(ctx)
    assert len(jobs) == before + 1 and jobs[-1].state == "queued"
    assert jobs[-1].payload == {"trigger": "collection", "collection": 6}
    assert worker.run_once().id == jobs[-1].id  # type: ignore[union-attr]
    refitted = _active(ctx)
    assert refitted.id != foreign and refitted.metadata["collection_models"] == 6

    # next due at 12: nothing at 7 ... 11
    paths = [p for p, _ in corpus.held_out[1:]] + [p for p, _ in corpus.seeded[:3]]
    for i, path in enumerate(paths[:5]):
        _ingest(ctx, worker, path, copy=1)
        assert _ready(ctx) == 7 + i and len(_rebuild_jobs(ctx)) == before + 1
    _ingest(ctx, worker, paths[5], copy=1)  # 12: doubled
    jobs = _rebuild_jobs(ctx)
    assert len(jobs) == before + 2 and jobs[-1].payload == {"trigger": "collection", "collection": 12}


def test_refits_are_off_by_default_and_before_any_vocabulary(tmp_path, data_dir):
    assert make_settings(data_dir).vocabulary_refit_at == 0
    assert refit.queue_refit_if_due(open_context(make_settings(data_dir))) is None  # off
    empty = open_context(make_settings(tmp_path / "empty", vocabulary_refit_at=1))
    assert refit.queue_refit_if_due(empty) is None  # no vocabulary: AUTO_VOCABULARY_MIN_MODELS' business


def test_a_refit_is_never_queued_beside_a_pending_rebuild(data_dir):
    ctx = open_context(make_settings(data_dir, vocabulary_refit_at=4))
    _activate_a_foreign_vocabulary(ctx)  # 12 ready, due at 4
    # many workers finishing ingests at once: one job
    got: list[int | None] = []
    threads = [threading.Thread(target=lambda: got.append(refit.queue_refit_if_due(ctx))) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    queued = [j for j in got if j is not None]
    assert len(queued) == 1
    # while it runs (claimed) nothing more is queued, nor beside an admin rebuild
    claimed = jobs_repo.claim(ctx.db, "w", 60.0, 3)
    assert claimed is not None and claimed.id == queued[0] and claimed.state == "running"
    assert refit.queue_refit_if_due(ctx) is None
    with ctx.db.write() as conn:
        jobs_repo.mark_failed(conn, claimed.id, "test")
        admin = jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={"size": 8})
    assert refit.queue_refit_if_due(ctx) is None
    assert [j.id for j in _rebuild_jobs(ctx)][-2:] == [claimed.id, admin]


def test_a_failed_refit_leaves_the_old_vocabulary_serving_and_waits_for_a_doubling(data_dir, monkeypatch):
    ctx = open_context(make_settings(data_dir, vocabulary_refit_at=4, max_attempts=2))
    old = _activate_a_foreign_vocabulary(ctx)
    live = LiveIndex(ctx)
    live.refresh()
    with ctx.db.read() as conn:
        mid = models_repo.ready_ids(conn)[0]
    before = [(h.model.id, h.distance) for h in search.similar(ctx, live, mid, 5).hits]

    def broken(*args, **kwargs):
        raise RuntimeError("encoding ran out of memory")

    monkeypatch.setattr(vocab_service, "encode_all", broken)  # after the new version's files are saved
    job_id = refit.queue_refit_if_due(ctx)
    assert job_id is not None
    Worker(ctx, "w").run_forever(exit_when_idle=True)  # both attempts fail
    with ctx.db.read() as conn:
        job = jobs_repo.get(conn, job_id)
    assert job is not None and job.state == "failed" and "out of memory" in (job.error or "")
    assert _active(ctx).id == old
    live.refresh()
    result = search.similar(ctx, live, mid, 5)
    assert result.vocabulary_id == old and [(h.model.id, h.distance) for h in result.hits] == before
    # not queued again at every ingest: the next try is at twice the 12 models it failed at
    assert refit.queue_refit_if_due(ctx) is None
    assert refit.refit_due_at(4, 0, refit.failed_at(job)) == 24


def test_searches_answer_from_the_old_pair_during_a_refit_then_from_the_new(data_dir, monkeypatch):
    ctx = open_context(make_settings(data_dir, vocabulary_refit_at=4))
    old = _activate_a_foreign_vocabulary(ctx)
    live = LiveIndex(ctx)
    live.refresh()
    with ctx.db.read() as conn:
        mid = models_repo.ready_ids(conn)[0]
    fitting, release = threading.Event(), threading.Event()
    real_fit = vocab_service.fit_vocabulary

    def slow_fit(*args, **kwargs):
        fitting.set()
        assert release.wait(60)
        return real_fit(*args, **kwargs)

    monkeypatch.setattr(vocab_service, "fit_vocabulary", slow_fit)
    job_id = refit.queue_refit_if_due(ctx)
    worker = threading.Thread(target=Worker(ctx, "w").run_once)
    worker.start()
    try:
        assert fitting.wait(60)
        for _ in range(3):  # mid-refit: the old pair answers, and says so
            live.refresh()
            result = search.similar(ctx, live, mid, 3)
            assert result.vocabulary_id == old and len(result.hits) == 3
    finally:
        release.set()
        worker.join(60)
    with ctx.db.read() as conn:
        job = jobs_repo.get(conn, job_id)  # type: ignore[arg-type]
    assert job is not None and job.state == "done", job
    new = job.timings["vocabulary_id"]
    assert new != old and _active(ctx).id == new
    live.refresh()
    result = search.similar(ctx, live, mid, 3)
    assert result.vocabulary_id == new and len(result.hits) == 3
    with ctx.db.read() as conn:  # every model encoded with the new version
        assert vocab_repo.ready_without_vector(conn, new) == []


def test_vocabulary_show_says_when_the_next_refit_is_due(data_dir, capsys, monkeypatch):
    assert main(["vocabulary", "show", "--data-dir", str(data_dir)]) == 0
    assert "refit on the collection: off" in capsys.readouterr().out
    monkeypatch.setenv("SHAPEBAG_VOCABULARY_REFIT_AT", "4")
    assert main(["vocabulary", "show", "--data-dir", str(data_dir)]) == 0
    assert "next at 24 ready models (12 now)" in capsys.readouterr().out  # the active one fit on 12
    _activate_a_foreign_vocabulary(open_context(make_settings(data_dir)))
    assert main(["vocabulary", "show", "--data-dir", str(data_dir)]) == 0
    assert "next at 4 ready models (12 now)" in capsys.readouterr().out


def test_the_admin_vocabulary_route_says_when_the_next_refit_is_due(data_dir):
    token = {"X-Admin-Token": "test-token-kkkkkkkkkkkkkkkkkkkkk"}
    with TestClient(create_app(make_settings(data_dir, workers=0))) as client:
        assert client.get("/admin/vocabulary", headers=token).json()["next_refit_at"] is None  # off
    with TestClient(create_app(make_settings(data_dir, workers=0, vocabulary_refit_at=10))) as client:
        info = client.get("/admin/vocabulary", headers=token).json()
        assert info["next_refit_at"] == 24 and info["metadata"]["collection_models"] == 12


def test_a_refit_with_descriptions_missing_counts_the_whole_collection(data_dir):
    """Fit on 5 of 12 descriptions, it still records 12 models: the next refit waits for 24, it is not
    queued again at once (2 × 5 < 12) after every ingest."""
    ctx = open_context(make_settings(data_dir, vocabulary_refit_at=4))
    _activate_a_foreign_vocabulary(ctx)
    with ctx.db.read() as conn:
        ids = models_repo.ready_ids(conn)
    for mid in ids[5:]:
        ctx.blobs.description_path(mid).unlink()
    job_id = refit.queue_refit_if_due(ctx)
    assert job_id is not None and Worker(ctx, "w").run_once().id == job_id  # type: ignore[union-attr]
    assert _active(ctx).metadata["collection_models"] == 12
    assert refit.queue_refit_if_due(ctx) is None and refit.refit_status(ctx) == (12, 24)
