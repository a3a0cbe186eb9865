"""The services end to end on each engine (SQLite, PostgreSQL: tests/pg_server.py): upload, worker,
vocabulary rebuild, live index, search by vector, a second replica's index, delete."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.services import catalog, ingestion
from app.services import partial as partial_service
from app.services.context import open_context
from app.services.live_index import LiveIndex
from app.storage import jobs as jobs_repo
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.worker.runner import Worker
from tests.conftest import make_settings, wait_for, wait_job
from tests.pg_server import db_url, pg_admin_url  # noqa: F401 (fixtures)

pytestmark = pytest.mark.slow
N = 6


def test_ingest_rebuild_search_delete(db_url, tmp_path, corpus):  # noqa: F811
    ctx = open_context(make_settings(tmp_path / "d", database_url=db_url))
    assert ctx.db.dialect == ("postgresql" if db_url else "sqlite")
    subs = [ingestion.submit(ctx, p.read_bytes(), p.name, label=c) for p, c in corpus.seeded[:N]]
    again = ingestion.submit(ctx, corpus.seeded[0][0].read_bytes(), "copy.obj")
    assert not again.created and again.model.id == subs[0].model.id  # identical content: the same model
    worker = Worker(ctx, "w")
    while worker.run_once() is not None:
        pass
    with ctx.db.write() as conn:
        rebuild = jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={"size": 8})
    assert worker.run_once().id == rebuild
    with ctx.db.read() as conn:
        assert models_repo.count_by_status(conn) == {"queued": 0, "ready": N, "failed": 0}
        assert jobs_repo.get(conn, rebuild).state == "done"
        vid = vocab_repo.active(conn).id
        ids, vectors, _ = vocab_repo.vectors(conn, vid)
    assert sorted(ids.tolist()) == sorted(s.model.id for s in subs)

    live, replica = LiveIndex(ctx), LiveIndex(ctx)  # two API replicas over one database
    live.refresh()
    replica.refresh()
    for i in range(N):  # each stored vector finds its own model first, identically on both replicas
        dist, got, _ = live.search(vectors[i], 3)
        assert got[0] == ids[i] and dist[0] == pytest.approx(0.0)
        dist2, got2, _ = replica.search(vectors[i], 3)
        np.testing.assert_array_equal(got, got2)
        np.testing.assert_allclose(dist, dist2)

    # a piece's peers read the candidates' stored vectors in one query: in order, NaN for an unknown id
    got = partial_service.stored_vectors(ctx, vid, [int(ids[1]), 10**9, int(ids[0])])
    np.testing.assert_array_equal(got[[0, 2]], vectors[[1, 0]])
    assert np.isnan(got[1]).all()

    gone = subs[1].model.id
    catalog.delete_model(ctx, live, gone)  # served by one replica...
    assert gone not in live.pair.index.ids() and gone in replica.pair.index.ids()
    replica.refresh()  # ...the other drops it at its next poll
    assert gone not in replica.pair.index.ids() and replica.pair.index.count == N - 1
    np.testing.assert_array_equal(np.sort(live.pair.index.ids()), np.sort(replica.pair.index.ids()))
    with ctx.db.read() as conn:
        assert models_repo.get(conn, gone) is None and vocab_repo.vector_of(conn, gone, vid) is None
    assert not ctx.blobs.mesh_path(subs[1].model.sha256, "obj").exists()


def test_read_only_commands_find_the_database(db_url, tmp_path, corpus, monkeypatch, capsys):  # noqa: F811
    from app import cli

    data_dir = tmp_path / ("cache" if db_url else "d")  # on PostgreSQL: a data dir holding no database
    ctx = open_context(make_settings(tmp_path / "d", database_url=db_url))
    with ctx.db.write() as conn:
        vocab_repo.insert(conn, path="vocabularies/1", trained_on=5, size=8, run="run5", metadata={})
    if db_url:
        monkeypatch.setenv("SHAPEBAG_DATABASE_URL", db_url)
    assert cli.main(["vocabulary", "show", "--data-dir", str(data_dir)]) == 0
    assert "v1: 8 words, run5, trained on 5 descriptors" in capsys.readouterr().out


def test_two_hosts_share_meshes_and_descriptions_through_the_database(db_url, tmp_path, corpus):  # noqa: F811
    if not db_url:
        pytest.skip("SQLite lives in one data directory: hosts without a shared filesystem need a server")
    def host(name: str):  # its own data directory: a cache, shared with no one
        return open_context(make_settings(tmp_path / name, database_url=db_url, blob_backend="database"))

    api, worker_host = host("api"), host("worker")
    subs = [ingestion.submit(api, p.read_bytes(), p.name, label=c) for p, c in corpus.seeded[:4]]
    worker = Worker(worker_host, "remote")
    while worker.run_once() is not None:  # reads each mesh from the database, stores its description there
        pass
    assert not (api.data_dir / "descriptions").exists()  # nothing came to the api host by a filesystem
    with api.db.write() as conn:
        rebuild = jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={"size": 8})
    Worker(api, "local").run_once()  # fits on descriptions fetched from the database
    with api.db.read() as conn:
        assert jobs_repo.get(conn, rebuild).state == "done"
        assert models_repo.count_by_status(conn)["ready"] == 4
        ids, vectors, _ = vocab_repo.vectors(conn, vocab_repo.active(conn).id)
    late = ingestion.submit(api, corpus.held_out[0][0].read_bytes(), corpus.held_out[0][0].name)
    assert worker.run_once().model_id == late.model.id  # encodes with the vocabulary the api host fitted
    with api.db.read() as conn:
        vid = vocab_repo.active(conn).id
        assert models_repo.get(conn, late.model.id).status == "ready"
        assert vocab_repo.vector_of(conn, late.model.id, vid) is not None
    live, remote = LiveIndex(api), LiveIndex(worker_host)  # a replica on each host
    live.refresh()
    remote.refresh()
    for v in vectors:
        dist, got, _ = live.search(v, 3)
        dist2, got2, _ = remote.search(v, 3)
        np.testing.assert_array_equal(got, got2)
        np.testing.assert_allclose(dist, dist2)
    catalog.delete_model(api, live, subs[0].model.id)
    fresh = host("new-host")
    assert not fresh.blobs.mesh_path(subs[0].model.sha256, "obj").exists()  # gone from the database
    assert fresh.blobs.mesh_path(subs[1].model.sha256, "obj").read_bytes() == corpus.seeded[1][0].read_bytes()


def test_the_api_with_its_embedded_worker(db_url, tmp_path, corpus):  # noqa: F811
    backend = "database" if db_url else "filesystem"
    settings = make_settings(
        tmp_path / "d", database_url=db_url, blob_backend=backend, auto_vocabulary_min_models=4,
        vocabulary_size=8,
    )
    with TestClient(create_app(settings)) as client:
        posted = [
            client.post("/models", files={"file": (p.name, p.read_bytes())}, data={"label": c})
            for p, c in corpus.seeded[:4]
        ]
        jobs = [r.json()["job_id"] for r in posted]
        assert all(wait_job(client, j)["state"] == "done" for j in jobs)
        wait_for(lambda: client.get("/readyz").status_code == 200, timeout_s=60)
        ready = client.get("/readyz").json()["checks"]
        assert ready["database"] and ready["indexed_models"] == 4 and ready["workers_alive"] == 1
        first = client.get("/models").json()["data"][0]["id"]
        assert client.get(f"/models/{first}/similar").json()["count"] == 3
        path, _ = corpus.held_out[0]
        r = client.post("/search", files={"file": (path.name, path.read_bytes())}, data={"k": 2})
        assert r.status_code == 200 and r.json()["count"] == 2
