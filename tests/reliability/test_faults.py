"""Faults with real processes on loopback: `shapebag serve` / `shapebag worker` killed with SIGKILL mid-work,
then restarted; afterwards the database, blobs, vocabulary and index agree and no model is lost."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.core.pipeline import ShapeDescription
from app.core.vocabulary import Vocabulary
from app.index import load_index
from app.main import create_app
from app.services import vocabularies
from app.services.context import open_context
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.storage.blobs import writer_tag
from app.worker.runner import Worker
from tests.conftest import make_settings, wait_for
from tests.reliability.helpers import (
    MULTIPART_HEADERS,
    Proc,
    env_for,
    multipart,
    refused_start,
    snapshot,
    start_server,
)

pytestmark = pytest.mark.slow
TOKEN = {"X-Admin-Token": "reliability-secret-kkkkkkkkkkkkk"}
HOOKS = Path(__file__).resolve().parent / "hooks"


def hold(target: str, barrier: Path) -> dict[str, str]:
    """Environment that holds `module:function` at `barrier` in a real process (hooks/sitecustomize.py)."""
    # the caller's PYTHONPATH kept: a checkout run with PYTHONPATH=. must serve its own app/
    path = os.pathsep.join(p for p in (str(HOOKS), os.environ.get("PYTHONPATH", "")) if p)
    return {"PYTHONPATH": path, "SHAPEBAG_TEST_HOLD": target, "SHAPEBAG_TEST_HOLD_FILE": str(barrier)}


def consistent(data_dir: Path) -> dict:
    """Offline check (no server running): every model's blobs exist and load, every ready model has a
    BoF for the active vocabulary, the vocabulary loads, and the saved index holds exactly those ids."""
    ctx = open_context(make_settings(data_dir))
    with ctx.db.read() as conn:
        models = [models_repo.get(conn, i) for (i,) in conn.execute("SELECT id FROM models").fetchall()]
        active = vocab_repo.active(conn)
        assert active is not None, "no active vocabulary"
        ids, _, _ = vocab_repo.vectors(conn, active.id)
        unfinished = jobs_repo.queue_depth(conn)
    assert unfinished == {"queued": 0, "running": 0}, unfinished
    ready = sorted(m.id for m in models if m.status == "ready")
    assert [m for m in models if m.status != "ready"] == [], "a model did not make it"
    for m in models:
        assert ctx.blobs.mesh_path(m.sha256, m.file_type).is_file(), f"mesh of model {m.id} lost"
        ShapeDescription.load(ctx.blobs.description_path(m.id))  # complete and readable
    assert sorted(int(i) for i in ids) == ready
    vocab = Vocabulary.load(vocabularies.inside_data_dir(ctx, active.path))
    index = load_index(ctx.settings.index_backend, ctx.index_path(active.id))
    assert index.dim == vocab.dimension(ctx.settings.encode.params())  # words (+ Shape-DNA when fused)
    assert sorted(index.ids().tolist()) == ready
    leftovers = [str(p) for p in data_dir.rglob(".*.tmp")]
    assert leftovers == [], f"temp files left behind: {leftovers}"  # a killed writer's are swept at start
    return {
        "models": len(models),
        "vocabulary": active.id,
        "indexed": index.count,
        "tmp_leftovers": leftovers,
    }


def job_state(data_dir: Path, job_id: int) -> str:
    ctx = open_context(make_settings(data_dir))
    with ctx.db.read() as conn:
        return jobs_repo.get(conn, job_id).state


def _job(http: httpx.Client, job_id: int) -> dict:
    return http.get(f"/jobs/{job_id}").json()


def _upload(http: httpx.Client, path: Path, label: str | None = None) -> dict:
    r = http.post(
        "/models",
        content=multipart(path.name, path.read_bytes(), {"label": label} if label else {}),
        headers=MULTIPART_HEADERS,
    )
    assert r.status_code == 202, r.text
    return r.json()


def test_killed_worker_job_completes_after_its_lease_with_exactly_one_model(tmp_path, corpus):
    data = tmp_path / "data"
    server, base = start_server(
        data, tmp_path / "server.log", SHAPEBAG_WORKERS="0", SHAPEBAG_LEASE_SECONDS="2"
    )
    workers: list[Proc] = []
    try:
        with httpx.Client(base_url=base, timeout=60) as http:
            path, label = corpus.seeded[0]
            job_id = _upload(http, path, label)["job_id"]
            env = env_for(data, SHAPEBAG_LEASE_SECONDS="2")
            barrier = tmp_path / "release-describe"  # the first worker's describe waits here, for ever
            held = {**env, **hold("app.services.ingestion:describe_and_view", barrier)}
            workers.append(Proc(["worker"], held, tmp_path / "worker1.log"))
            wait_for(lambda: Path(f"{barrier}.entered").exists(), timeout_s=120)
            workers[0].kill9()  # mid-describe, for certain
            job = _job(http, job_id)
            assert job["state"] == "running" and job["attempts"] == 1, job
            workers.append(Proc(["worker"], env, tmp_path / "worker2.log"))
            job = wait_for(
                lambda: (j := _job(http, job_id))["state"] in ("done", "failed") and j, timeout_s=180
            )
            assert job["state"] == "done" and job["attempts"] == 2, job
            models = http.get("/models").json()
            assert models["count"] == 1 and models["data"][0]["status"] == "ready"
    finally:
        for w in workers:
            w.stop()
        server.stop()


def test_server_killed_during_ingestion_loses_nothing(data_dir, corpus, tmp_path):
    extra = {"SHAPEBAG_WORKERS": "1", "SHAPEBAG_LEASE_SECONDS": "2"}
    server, base = start_server(data_dir, tmp_path / "a.log", **extra)
    with httpx.Client(base_url=base, timeout=60) as http:
        accepted = [_upload(http, p, label) for p, label in corpus.held_out]
        running = lambda: any(_job(http, a["job_id"])["state"] == "running" for a in accepted[1:])  # noqa: E731
        wait_for(running, timeout_s=120, interval_s=0.01)
    server.kill9()  # the server, its embedded worker and its query pool, mid-ingestion
    states = [job_state(data_dir, a["job_id"]) for a in accepted]
    server, base = start_server(data_dir, tmp_path / "b.log", **extra)
    try:
        with httpx.Client(base_url=base, timeout=60) as http:
            for a in accepted:
                wait_for(lambda a=a: _job(http, a["job_id"])["state"] == "done", timeout_s=180)
            total = len(corpus.seeded) + len(corpus.held_out)
            wait_for(lambda: http.get("/readyz").json()["checks"]["indexed_models"] == total, timeout_s=30)
    finally:
        server.stop()  # graceful: saves the index
    report = consistent(data_dir)
    print(f"ingest jobs when killed: {states}; after restart: {report}")
    assert report["models"] == report["indexed"] == len(corpus.seeded) + len(corpus.held_out)


def test_server_killed_during_vocabulary_rebuild_recovers(data_dir, tmp_path):
    extra = {"SHAPEBAG_WORKERS": "1", "SHAPEBAG_LEASE_SECONDS": "2"}
    before = consistent(data_dir)
    # the worker's fit waits at a barrier (tests/reliability/hooks/sitecustomize.py): the kill lands
    # mid-rebuild for certain, however fast or loaded the machine
    barrier = tmp_path / "release-fit"
    held = hold("app.services.vocabularies:fit_vocabulary", barrier)
    server, base = start_server(data_dir, tmp_path / "a.log", **extra, **held)
    with httpx.Client(base_url=base, timeout=60) as http:
        wait_for(lambda: http.get("/readyz").status_code == 200, timeout_s=60)
        r = http.post("/admin/vocabulary/rebuild", json={"size": 24, "run": "run5"}, headers=TOKEN)
        assert r.status_code == 202, r.text
        job_id = r.json()["job_id"]
        wait_for(lambda: Path(f"{barrier}.entered").exists(), timeout_s=120)
        server.kill9()
    state_at_kill = job_state(data_dir, job_id)
    assert state_at_kill == "running", state_at_kill  # killed mid-rebuild, not before or after
    server, base = start_server(data_dir, tmp_path / "b.log", **extra)
    try:
        with httpx.Client(base_url=base, timeout=60) as http:
            job = wait_for(
                lambda: (j := _job(http, job_id))["state"] in ("done", "failed") and j, timeout_s=120
            )
            assert job["state"] == "done", job
            wait_for(lambda: http.get("/readyz").status_code == 200, timeout_s=60)
            vocab = lambda: http.get("/admin/vocabulary", headers=TOKEN).json()  # noqa: E731
            # the live index follows the swap on its next poll
            wait_for(lambda: vocab()["indexed_models"] == before["models"], timeout_s=30)
            assert vocab()["words"] == 24
    finally:
        server.stop()
    after = consistent(data_dir)
    assert (
        after["models"] == after["indexed"] == before["models"] and after["vocabulary"] > before["vocabulary"]
    )
    print(f"rebuild job was {state_at_kill} when killed; after restart: {after}")


def test_rebuild_survives_a_vocabulary_directory_left_by_a_kill(data_dir):
    """Killed after the vocabulary files were renamed into place but before the row was committed: the
    next rebuild gets the same id (the insert was rolled back) and must not trip over the old files."""
    ctx = open_context(make_settings(data_dir))
    with ctx.db.read() as conn:
        next_id = max(v.id for v in vocab_repo.all_versions(conn)) + 1
    debris = ctx.vocabulary_dir(next_id)
    debris.mkdir(parents=True)
    (debris / "centers.npy").write_bytes(b"half a file")
    with ctx.db.write() as conn:
        job_id = jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={"size": 8})
    Worker(ctx, "after-crash").run_once()
    with ctx.db.read() as conn:
        assert jobs_repo.get(conn, job_id).state == "done"
        active = vocab_repo.active(conn)
    assert active.id == next_id and Vocabulary.load(ctx.data_dir / active.path).size == 8


def test_each_swap_prunes_versions_nobody_serves_including_one_left_by_a_killed_rebuild(data_dir):
    """A rebuild killed after it registered its version (row + files, inactive) leaves an orphan; the
    next swap deletes it, rows, vectors and files, and keeps the version it replaced for one more round."""
    ctx = open_context(make_settings(data_dir))

    def rebuild() -> int:
        with ctx.db.write() as conn:
            job_id = jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={"size": 8})
        Worker(ctx, "pruner").run_once()
        with ctx.db.read() as conn:
            job = jobs_repo.get(conn, job_id)
        assert job.state == "done", job
        return int(job.timings["vocabulary_id"])

    def bof_rows(vid: int) -> int:
        with ctx.db.read() as conn:
            return conn.execute("SELECT COUNT(*) FROM bof WHERE vocabulary_id = ?", (vid,)).fetchone()[0]

    with ctx.db.read() as conn:
        first = vocab_repo.active(conn).id
        ready = len(models_repo.ready_ids(conn))
    orphan = vocabularies.register(
        ctx, Vocabulary.fit_features(np.random.default_rng(0).random((50, 4)), size=8), activate=False
    )
    with ctx.db.write() as conn:  # the killed rebuild had stored some vectors too
        vocab_repo.put_vector(conn, models_repo.ready_ids(conn)[0], orphan, np.ones(8, np.float32))
    assert ctx.vocabulary_dir(orphan).is_dir() and bof_rows(orphan) == 1

    second = rebuild()
    with ctx.db.read() as conn:
        ids = [v.id for v in vocab_repo.all_versions(conn)]
    assert ids == [first, second]  # the orphan is gone, the replaced version stays
    assert bof_rows(orphan) == 0 and not ctx.vocabulary_dir(orphan).exists()
    assert bof_rows(first) == ready and ctx.vocabulary_dir(first).is_dir()

    third = rebuild()
    with ctx.db.read() as conn:
        assert [v.id for v in vocab_repo.all_versions(conn)] == [second, third]
        assert vocab_repo.active(conn).id == third
    assert bof_rows(first) == 0 and not ctx.vocabulary_dir(first).exists()
    assert bof_rows(third) == ready
    assert load_index(ctx.settings.index_backend, ctx.index_path(third)).count == ready


def test_unwritable_data_dir_refuses_to_start_with_one_line(tmp_path):
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("a regular file where the data directory's parent should be")
    env = env_for(blocker / "data")
    code, lines = refused_start(env)
    assert code == 2 and len(lines) == 1 and "cannot use the data directory" in lines[0], lines


@pytest.mark.parametrize(("code", "status"), [(errno.ENOSPC, 507), (errno.EROFS, 503)])
def test_full_or_read_only_disk_answers_clearly_and_stores_nothing(
    data_dir, corpus, monkeypatch, code, status
):
    import app.storage.blobs as blobs

    path, _ = corpus.held_out[0]
    body = multipart(path.name, path.read_bytes())
    with TestClient(create_app(make_settings(data_dir))) as client:
        before = snapshot(data_dir)

        def no_space(fd: int) -> None:
            raise OSError(code, "simulated")

        monkeypatch.setattr(blobs.os, "fsync", no_space)  # the blob is half written when it fails
        r = client.post("/models", content=body, headers=MULTIPART_HEADERS)
        monkeypatch.undo()
        assert r.status_code == status, r.text
        assert "nothing was saved" in r.json()["error"]["message"]
        assert status != 503 or r.headers["retry-after"]
        assert snapshot(data_dir) == before  # no row, no blob, no temp file
        assert client.post("/models", content=body, headers=MULTIPART_HEADERS).status_code == 202


def test_old_temp_debris_is_swept_at_start_and_fresh_temp_files_are_left(data_dir):
    old_file = data_dir / "descriptions" / ".14.npz.2tet26mm.tmp"
    old_dir = data_dir / "vocabularies" / ".7.k3_x9q2"
    fresh = data_dir / "meshes" / ".abc.obj.q1w2e3.tmp"  # maybe another process writing right now
    for p in (old_file, fresh):
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"half a file")
    old_dir.mkdir()
    (old_dir / "centers.npy").write_bytes(b"half")
    long_ago = time.time() - 2 * 3600
    for p in (old_file, old_dir):
        os.utime(p, (long_ago, long_ago))
    # tagged by atomic_write with <pid>@<host>: a dead writer's file goes at once, a live one's stays
    host = writer_tag().split("@", 1)[1]
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    by_dead = data_dir / "descriptions" / f".15.npz.{dead.pid}@{host}.a1b2c3.tmp"
    by_live = data_dir / "descriptions" / f".16.npz.{os.getpid()}@{host}.d4e5f6.tmp"
    by_other_host = data_dir / "meshes" / f".ab.obj.{dead.pid}@another-container.g7h8i9.tmp"
    for p in (by_dead, by_live, by_other_host):
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"half a file")
    kept = snapshot(data_dir).files
    with TestClient(create_app(make_settings(data_dir))) as client:
        assert client.get("/healthz").status_code == 200
    assert not old_file.exists() and not old_dir.exists() and fresh.exists()
    assert not by_dead.exists() and by_live.exists() and by_other_host.exists()
    assert all((data_dir / rel).exists() for rel in kept if ".tmp" not in rel and ".7." not in rel)
    for p in (fresh, by_live, by_other_host):  # not debris of this test's server: leave none behind
        p.unlink()


def test_worker_on_an_unwritable_data_dir_exits_with_a_clear_error(tmp_path):
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("a regular file")
    p = subprocess.run(
        [sys.executable, "-m", "app.cli", "worker", "--exit-when-idle"],
        env=env_for(blocker / "data"),
        capture_output=True,
        text=True,
        timeout=120,
    )
    last = p.stderr.strip().splitlines()[-1]
    assert p.returncode == 2, p.stderr
    assert last.startswith("shapebag worker: error: cannot use the data directory"), p.stderr
