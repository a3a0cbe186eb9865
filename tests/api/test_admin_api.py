"""Admin auth; vocabulary rebuild swaps versions while searches keep answering; restart reconciliation."""

from __future__ import annotations

import threading

import numpy as np
from fastapi.testclient import TestClient

from app.main import create_app
from app.services.context import open_context
from app.storage import vocabularies as vocab_repo
from tests.conftest import TEST_WORDS, make_settings, wait_for, wait_job

TOKEN = {"X-Admin-Token": "test-token-kkkkkkkkkkkkkkkkkkkkk"}


def test_admin_routes_need_the_token(data_dir):
    with TestClient(create_app(make_settings(data_dir, workers=0))) as client:
        for method, url in [
            ("post", "/admin/vocabulary/rebuild"),
            ("get", "/admin/vocabulary"),
            ("post", "/admin/index/rebuild"),
        ]:
            for headers in ({}, {"X-Admin-Token": "wrong"}, {"X-Admin-Token": ""}):
                r = getattr(client, method)(url, headers=headers)
                assert r.status_code == 401, (url, headers)
                assert r.json()["error"]["code"] == "unauthorized"
        info = client.get("/admin/vocabulary", headers=TOKEN).json()
        assert info["words"] == TEST_WORDS and info["versions"] == 1 and info["trained_on_descriptors"] > 0
        r = client.post("/admin/vocabulary/rebuild", headers=TOKEN, json={"size": 8, "run": "nope"})
        assert r.status_code == 422


def test_default_admin_token_is_refused_outside_dev_mode(tmp_path):
    import pytest

    with pytest.raises(ValueError, match="ADMIN_TOKEN"):
        create_app(make_settings(tmp_path, dev_mode=False, admin_token="change-me"))
    create_app(make_settings(tmp_path, dev_mode=False, admin_token="s3cret" * 6))  # a real secret is fine


def test_rebuild_swaps_versions_while_searches_keep_answering(data_dir, corpus):
    with TestClient(create_app(make_settings(data_dir, workers=2))) as client:
        models = client.get("/models", params={"limit": 100}).json()["data"]
        old = client.get("/admin/vocabulary", headers=TOKEN).json()["id"]
        seen: list[tuple[int, int]] = []
        stop = threading.Event()

        def keep_searching():
            i = 0
            while not stop.is_set():
                r = client.get(f"/models/{models[i % len(models)]['id']}/similar", params={"k": 3})
                seen.append((r.status_code, r.json().get("vocabulary_id", -1)))
                i += 1

        searcher = threading.Thread(target=keep_searching)
        searcher.start()
        try:
            job = client.post("/admin/vocabulary/rebuild", headers=TOKEN, json={"size": 8, "seed": 1}).json()
            # a second request while one is pending answers with the same job
            assert client.post("/admin/vocabulary/rebuild", headers=TOKEN).json()["job_id"] == job["job_id"]
            path, label = corpus.held_out[1]  # ingested while the rebuild runs
            up = client.post("/models", files={"file": (path.name, path.read_bytes())}, data={"label": label})
            done = wait_job(client, job["job_id"])
            assert done["state"] == "done", done
            assert wait_job(client, up.json()["job_id"])["state"] == "done"
            new = done["result"]["vocabulary_id"]
            assert new != old
            wait_for(lambda: seen and seen[-1][1] == new, timeout_s=20)
        finally:
            stop.set()
            searcher.join()
        assert all(code == 200 for code, _ in seen), {c for c, _ in seen}
        versions = [v for _, v in seen]
        assert versions[0] == old and versions[-1] == new
        assert versions == sorted(versions)  # old answers, then new ones: never back
        info = client.get("/admin/vocabulary", headers=TOKEN).json()
        assert info["id"] == new and info["words"] == 8 and info["versions"] == 2

        # the model ingested during the rebuild ends encoded with the new vocabulary, and is found
        ctx = open_context(make_settings(data_dir))
        with ctx.db.read() as conn:
            assert vocab_repo.vector_of(conn, up.json()["model_id"], new) is not None

        def first_is_upload():
            r = client.post("/search", files={"file": (path.name, path.read_bytes())}, data={"k": "3"})
            return r.status_code == 200 and r.json()["data"][0]["model_id"] == up.json()["model_id"]

        wait_for(first_is_upload, timeout_s=20)


def _answers(client, models) -> list[list[tuple[int, float]]]:
    out = []
    for m in models:
        hits = client.get(f"/models/{m['id']}/similar", params={"k": 5}).json()["data"]
        out.append([(h["model_id"], round(h["distance"], 5)) for h in hits])
    return out


def test_restart_reconciles_a_missing_or_corrupt_index(data_dir):
    settings = make_settings(data_dir, workers=0)
    with TestClient(create_app(settings)) as client:
        models = client.get("/models", params={"limit": 100}).json()["data"]
        before = _answers(client, models)
        vid = client.get("/admin/vocabulary", headers=TOKEN).json()["id"]
    ctx = open_context(settings)
    index_file = ctx.index_path(vid)
    assert index_file.is_file()  # saved at shutdown
    index_file.unlink()
    with TestClient(create_app(settings)) as client:
        assert client.get("/readyz").json()["checks"]["indexed_models"] == len(models)
        assert _answers(client, models) == before
    index_file.write_bytes(b"garbage")
    with TestClient(create_app(settings)) as client:
        assert _answers(client, models) == before
    assert index_file.stat().st_size > 100  # rewritten


def test_new_encode_settings_apply_from_the_next_vocabulary_rebuild(data_dir):
    """A version keeps the encoding it was registered with (its vectors and its fusion scale agree): an
    index rebuild under other settings re-encodes the same way; a vocabulary rebuild fits a new
    version, encoded as the settings now say."""
    from app.config import EncodeSettings

    settings = make_settings(data_dir, encode=EncodeSettings(mode="hard"))  # the seed was encoded "soft"
    ctx = open_context(settings)
    with ctx.db.read() as conn:
        old = vocab_repo.active(conn).id
        soft_ids, soft, _ = vocab_repo.vectors(conn, old)
    with TestClient(create_app(settings)) as client:
        models = client.get("/models", params={"limit": 100}).json()["data"]
        before = _answers(client, models)
        assert all(hits[0][1] > 0 for hits in before)  # different shapes never coincide
        job = client.post("/admin/index/rebuild", headers=TOKEN).json()
        done = wait_job(client, job["job_id"])
        assert done["state"] == "done" and done["result"]["models"] == len(models)
        with ctx.db.read() as conn:
            again_ids, again, _ = vocab_repo.vectors(conn, old)
        np.testing.assert_allclose(again[np.argsort(again_ids)], soft[np.argsort(soft_ids)], atol=1e-6)
        assert _answers(client, models) == before
        job = client.post("/admin/vocabulary/rebuild", headers=TOKEN, json={"size": TEST_WORDS}).json()
        assert wait_job(client, job["job_id"])["state"] == "done"
        wait_for(lambda: _answers(client, models) != before, timeout_s=20)  # the live index follows
    with ctx.db.read() as conn:
        new = vocab_repo.active(conn)
        hard_ids, hard, _ = vocab_repo.vectors(conn, new.id)
    assert new.id != old and new.metadata["vectors_encoding"]["mode"] == "hard"
    assert sorted(soft_ids) == sorted(hard_ids)
    hard, soft = hard[np.argsort(hard_ids)], soft[np.argsort(soft_ids)]  # rows come in seq order: align by id
    words = TEST_WORDS
    assert ((soft[:, :words] > 0).sum(axis=1) > (hard[:, :words] > 0).sum(axis=1)).all()  # hard: fewer words
