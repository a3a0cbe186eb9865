"""Models, vocabulary versions and BoF vectors, on SQLite and PostgreSQL (tests/storage/conftest.py)."""

from __future__ import annotations

import numpy as np
import pytest

from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo


def _model(conn, sha: str, label: str | None = "chair", metadata: dict | None = None) -> int:
    meta = metadata or {}
    return models_repo.insert(
        conn, name=f"m-{sha}", label=label, metadata=meta, sha256=sha, file_type="obj", size_bytes=10
    )


def test_models_insert_get_page_and_counts(db):
    with db.write() as conn:
        a = _model(conn, "a", metadata={"source": "scan", "n": [1, 2]})
        b = _model(conn, "b", label="table")
        c = _model(conn, "c", label=None)
        models_repo.set_ready(conn, a, 250)
        models_repo.set_ready(conn, b, 300)
        models_repo.set_failed(conn, c, "mesh has no faces")
    assert len({a, b, c}) == 3 and min(a, b, c) >= 1
    with db.read() as conn:
        got = models_repo.get(conn, a)
        assert got.metadata == {"source": "scan", "n": [1, 2]} and got.n_vertices == 250
        assert got.status == "ready" and got.error is None
        assert models_repo.get_by_sha256(conn, "c").error == "mesh has no faces"
        assert models_repo.get(conn, 10_000) is None
        assert set(models_repo.get_many(conn, [a, c, 10_000])) == {a, c}
        rows, total = models_repo.page(conn, status="ready", limit=1, offset=0)
        assert total == 2 and [r.id for r in rows] == [b]  # newest first
        rows, total = models_repo.page(conn, label="chair")
        assert total == 1 and rows[0].id == a
        assert models_repo.ready_ids(conn) == sorted([a, b])
        assert models_repo.ids_with_label(conn, "table") == [b]
        assert models_repo.label_counts(conn) == [("chair", 1), ("table", 1)]
        assert models_repo.count_by_status(conn) == {"queued": 0, "ready": 2, "failed": 1}


def test_content_hash_is_unique(db):
    with db.write() as conn:
        _model(conn, "same")
    with pytest.raises(Exception, match="(?i)unique"), db.write() as conn:
        _model(conn, "same")
    with db.read() as conn:  # the failed transaction left nothing behind
        assert models_repo.count_by_status(conn)["queued"] == 1


def test_a_failed_write_rolls_back_everything(db):
    with pytest.raises(RuntimeError), db.write() as conn:
        _model(conn, "x")
        jobs_repo.enqueue(conn, "ingest")
        raise RuntimeError("half-way")
    with db.read() as conn:
        assert models_repo.get_by_sha256(conn, "x") is None
        assert jobs_repo.queue_depth(conn) == {"queued": 0, "running": 0}


def test_one_active_vocabulary_and_vectors_by_seq(db):
    with db.write() as conn:
        m1, m2 = _model(conn, "1"), _model(conn, "2")
        models_repo.set_ready(conn, m1, 10)
        models_repo.set_ready(conn, m2, 10)
        v1 = vocab_repo.insert(conn, path="v1", trained_on=2, size=4, run="run5", metadata={"k": 1})
        v2 = vocab_repo.insert(conn, path="v2", trained_on=2, size=4, run="run5", metadata={})
        vocab_repo.activate(conn, v1)
    with db.write() as conn:
        vocab_repo.activate(conn, v2)
        vocab_repo.set_path(conn, v2, "vocabularies/2")
    with db.read() as conn:
        act = vocab_repo.active(conn)
        assert act.id == v2 and act.active is True and act.path == "vocabularies/2"
        assert [v.active for v in vocab_repo.all_versions(conn)] == [False, True]
        assert vocab_repo.get(conn, v1).metadata == {"k": 1}

    vec1 = np.array([0.5, 0.25, 0.0, 0.25], np.float32)
    with db.write() as conn:
        vocab_repo.put_vector(conn, m1, v2, vec1)
        vocab_repo.put_vector(conn, m2, v2, vec1 * 2)
        vocab_repo.put_vector(conn, m1, v1, vec1)
    with db.read() as conn:
        ids, vecs, seq = vocab_repo.vectors(conn, v2)
        assert ids.tolist() == [m1, m2] and vecs.dtype == np.float32
        np.testing.assert_array_equal(vecs, np.stack([vec1, vec1 * 2]))
        assert vocab_repo.ready_without_vector(conn, v1) == [m2]
        assert vocab_repo.max_seq(conn) >= seq
    with db.write() as conn:  # a replaced vector gets a newer seq: a poller after `seq` sees only it
        vocab_repo.put_vector(conn, m1, v2, vec1 * 3)
    with db.read() as conn:
        ids, vecs, newer = vocab_repo.vectors(conn, v2, after_seq=seq)
        assert ids.tolist() == [m1] and newer > seq
        np.testing.assert_array_equal(vocab_repo.vector_of(conn, m1, v2), vec1 * 3)
        assert vocab_repo.vector_of(conn, m2, v1) is None
        # a batch by model id: the version's vectors of those it has, nothing for an empty list
        got = vocab_repo.vectors_of(conn, v2, [m2, m1, 999])
        assert sorted(got) == [m1, m2]
        np.testing.assert_array_equal(got[m1], vec1 * 3)
        np.testing.assert_array_equal(got[m2], vec1 * 2)
        assert list(vocab_repo.vectors_of(conn, v1, [m1, m2])) == [m1]
        assert vocab_repo.vectors_of(conn, v1, []) == {}


def test_a_version_records_how_its_vectors_are_encoded(db):
    encoding = {"mode": "soft", "sigma_scale": 1.0, "keypoints_only": False, "area_weighted": True}
    with db.write() as conn:
        vid = vocab_repo.insert(conn, path="v", trained_on=10, size=4, run="run5",
                                metadata={"seed": 3, "vectors_encoding": encoding})
        model = _model(conn, "enc")
        vocab_repo.put_vector(conn, model, vid, np.ones(4))
        vocab_repo.delete_vector(conn, model, vid)
        vocab_repo.delete_vector(conn, model, vid + 1)  # no such version: nothing
    with db.read() as conn:
        assert vocab_repo.get(conn, vid).metadata == {"seed": 3, "vectors_encoding": encoding}
        assert [v.id for v in vocab_repo.all_versions(conn)] == [vid]
        assert vocab_repo.vector_of(conn, model, vid) is None


def test_deletes_cascade_and_never_remove_the_active_version(db):
    with db.write() as conn:
        m = _model(conn, "1")
        models_repo.set_ready(conn, m, 10)
        old = vocab_repo.insert(conn, path="old", trained_on=1, size=2, run="run5", metadata={})
        new = vocab_repo.insert(conn, path="new", trained_on=1, size=2, run="run5", metadata={})
        vocab_repo.activate(conn, new)
        vocab_repo.put_vector(conn, m, old, np.ones(2, np.float32))
        vocab_repo.put_vector(conn, m, new, np.ones(2, np.float32))
    with db.write() as conn:
        assert vocab_repo.delete_inactive(conn, [old, new]) == [old]
    with db.read() as conn:
        assert vocab_repo.vector_of(conn, m, old) is None  # its BoF went with it
        assert vocab_repo.vector_of(conn, m, new) is not None
    with db.read() as conn:
        _, seen = models_repo.deleted_since(conn, 0)
    with db.write() as conn:
        models_repo.delete(conn, m)
        models_repo.delete(conn, m)  # already gone: not logged twice
    with db.read() as conn:
        assert vocab_repo.vectors(conn, new)[0].size == 0
        ids, last = models_repo.deleted_since(conn, seen)
        assert ids == [m] and last > seen and models_repo.deleted_since(conn, last) == ([], last)


def test_heartbeats_and_live_workers(db):
    jobs_repo.heartbeat(db, "w1", 11)
    jobs_repo.heartbeat(db, "w1", 12)  # upsert
    jobs_repo.heartbeat(db, "w2", 13)
    with db.read() as conn:
        assert jobs_repo.live_workers(conn, within_s=3600) == 2
        assert conn.execute("SELECT pid FROM workers WHERE name = ?", ("w1",)).fetchone()["pid"] == 12
    jobs_repo.forget_worker(db, "w2")
    with db.read() as conn:
        assert jobs_repo.live_workers(conn, within_s=3600) == 1


def test_job_outcomes_and_timings(db):
    with db.write() as conn:
        mid = _model(conn, "j")
        jid = jobs_repo.enqueue(conn, "ingest", model_id=mid, payload={"retry": True})
    job = jobs_repo.claim(db, "w", lease_seconds=60, max_attempts=3)
    assert job.id == jid and job.payload == {"retry": True} and job.lease_until is not None
    with db.write() as conn:
        jobs_repo.release_for_retry(conn, jid, "transient")
    with db.read() as conn:
        back = jobs_repo.get(conn, jid)
        assert back.state == "queued" and back.error == "transient" and back.worker is None
    jobs_repo.claim(db, "w", lease_seconds=60, max_attempts=3)
    with db.write() as conn:
        jobs_repo.mark_done(conn, jid, {"load": 0.5, "describe.spectrum": 1.25})
    with db.read() as conn:
        done = jobs_repo.latest_for_model(conn, mid)
        assert done.state == "done" and done.error is None and done.lease_until is None
        assert done.timings == {"load": 0.5, "describe.spectrum": 1.25} and done.attempts == 2
    with pytest.raises(ValueError), db.write() as conn:
        jobs_repo.enqueue(conn, "no-such-kind")


def test_a_write_waits_for_another_only_up_to_the_busy_timeout(db, db_url, tmp_path):
    # the holder keeps its transaction open until the waiter has given up: no race on timing
    impatient = type(db)(db_url or tmp_path / "shapebag.db", busy_timeout_s=0.2)
    with db.write() as conn:
        _model(conn, "held")
        with pytest.raises(Exception, match="(?i)lock"), impatient.write() as other:
            _model(other, "waiting")
    with db.read() as conn:
        assert models_repo.get_by_sha256(conn, "waiting") is None
        assert models_repo.get_by_sha256(conn, "held") is not None
