"""The doors: the admin token, start-up refusal, CORS, no pickle, files only from the data directory,
upload names never used as paths, a non-root container."""

from __future__ import annotations

import hmac
import re
import sqlite3
from pathlib import Path
from types import SimpleNamespace

import pytest
from fastapi.testclient import TestClient

from app.api import deps
from app.config import DEFAULT_ADMIN_TOKEN
from app.main import create_app
from app.services import vocabularies
from app.services.context import open_context
from app.storage import vocabularies as vocab_repo
from tests.conftest import make_settings, wait_job
from tests.reliability.helpers import env_for, refused_start

REPO = Path(__file__).resolve().parents[2]


def test_admin_token_is_compared_in_constant_time_and_required(data_dir, monkeypatch):
    compared = []  # behaviour, not source text: every decision goes through hmac.compare_digest

    def spy(a, b):
        compared.append((a, b))
        return hmac.compare_digest(a, b)

    monkeypatch.setattr(deps, "hmac", SimpleNamespace(compare_digest=spy))
    with TestClient(
        create_app(make_settings(data_dir, admin_token="s3cret-token-kkkkkkkkkkkkkkkkkkk"))
    ) as client:
        assert client.get("/admin/vocabulary").status_code == 401
        for wrong in (
            "s3cret-tokeN",
            "s3cret-toke",
            "s3cret-token-kkkkkkkkkkkkkkkkkkk ",
            "",
            "x" * 10_000,
            "s3cret-tökén".encode(),
        ):
            r = client.get("/admin/vocabulary", headers={"X-Admin-Token": wrong})
            assert r.status_code == 401 and r.headers["www-authenticate"], wrong
        assert (
            client.get(
                "/admin/vocabulary", headers={"X-Admin-Token": "s3cret-token-kkkkkkkkkkkkkkkkkkk"}
            ).status_code
            == 200
        )
        assert client.post("/admin/vocabulary/rebuild", json={"size": 8}).status_code == 401
    # each presented token (the five wrong ones, the right one) was compared in constant time
    assert (b"s3cret-token-kkkkkkkkkkkkkkkkkkk", b"s3cret-token-kkkkkkkkkkkkkkkkkkk") in compared and len(
        compared
    ) >= 6


@pytest.mark.parametrize("token", [DEFAULT_ADMIN_TOKEN, ""])
def test_refuses_to_start_with_a_default_or_empty_token_outside_dev_mode(tmp_path, token):
    with pytest.raises(ValueError, match="SHAPEBAG_ADMIN_TOKEN"):
        create_app(make_settings(tmp_path / "d", dev_mode=False, admin_token=token))
    create_app(make_settings(tmp_path / "d", dev_mode=True, admin_token=token))  # dev mode: allowed


def test_serve_without_a_token_exits_with_one_line(tmp_path):
    env = env_for(tmp_path / "d")
    env.pop("SHAPEBAG_ADMIN_TOKEN")
    env.pop("SHAPEBAG_DEV_MODE", None)
    code, lines = refused_start(env)
    assert code == 2 and len(lines) == 1 and "ADMIN_TOKEN" in lines[0], lines


def test_cors_is_closed_by_default_and_open_only_to_configured_origins(tmp_path):
    evil = {"Origin": "https://evil.example"}
    preflight = {**evil, "Access-Control-Request-Method": "POST"}
    with TestClient(create_app(make_settings(tmp_path / "a"))) as client:
        assert "access-control-allow-origin" not in client.get("/healthz", headers=evil).headers
        assert "access-control-allow-origin" not in client.options("/search", headers=preflight).headers
    settings = make_settings(tmp_path / "b", cors_origins=["https://ok.example"])
    with TestClient(create_app(settings)) as client:
        ok = client.get("/healthz", headers={"Origin": "https://ok.example"})
        assert ok.headers["access-control-allow-origin"] == "https://ok.example"
        assert "access-control-allow-origin" not in client.get("/healthz", headers=evil).headers


def test_no_pickle_anywhere_in_the_package():
    pattern = re.compile(
        r"\bimport (c?pickle|dill|shelve|marshal)\b|\bpickle\.|allow_pickle\s*=\s*True|joblib\.load"
    )
    found = [
        f"{p.relative_to(REPO)}:{i}: {line.strip()}"
        for p in sorted((REPO / "app").rglob("*.py"))
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if pattern.search(line)
    ]
    assert found == []
    np_loads = [
        f"{p.relative_to(REPO)}:{i}"
        for p in sorted((REPO / "app").rglob("*.py"))
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if "np.load(" in line and "allow_pickle=False" not in line
    ]
    assert np_loads == [], "every np.load says allow_pickle=False"


def test_vocabulary_and_index_files_are_read_only_from_the_data_dir(data_dir, tmp_path):
    ctx = open_context(make_settings(data_dir))
    with ctx.db.read() as conn:
        record = vocab_repo.active(conn)
    assert ctx.index_path(record.id).resolve().is_relative_to(data_dir.resolve())
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    for path in ("../elsewhere", str(outside), "vocabularies/../../elsewhere", ""):
        with pytest.raises(ValueError, match="inside the data directory"):
            vocabularies.inside_data_dir(ctx, path)
    # a tampered row pointing outside is refused when loaded
    conn = sqlite3.connect(data_dir / "shapebag.db")
    conn.execute("UPDATE vocabularies SET path = ? WHERE id = ?", (str(outside), record.id))
    conn.commit()
    conn.close()
    vocabularies._cache.clear()
    with ctx.db.read() as conn:
        tampered = vocab_repo.get(conn, record.id)
    assert tampered.path == str(outside)
    with pytest.raises(ValueError, match="inside the data directory"):
        vocabularies.load_vocabulary(ctx, tampered)


def test_upload_names_are_never_used_as_paths(data_dir, corpus, tmp_path):
    path, _ = corpus.held_out[0]
    with TestClient(create_app(make_settings(data_dir))) as client:
        r = client.post(
            "/models",
            files={"file": ("evil.obj", path.read_bytes())},
            data={"name": "../../../../tmp/evil-name", "label": "../../etc"},
        )
        assert r.status_code == 202
        assert wait_job(client, r.json()["job_id"])["state"] == "done"
        model = client.get(f"/models/{r.json()['model_id']}").json()
        assert model["name"] == "../../../../tmp/evil-name"  # stored as text, shown as text
        assert client.get(f"/models/{model['id']}/thumbnail.png").status_code == 200
    names = [p.name for p in data_dir.rglob("*") if p.is_file()]
    assert not any("evil" in n or n == "etc" for n in names)
    blob_names = {p.name for p in (data_dir / "meshes").rglob("*.*")}
    assert f"{model['sha256']}.obj" in blob_names
    assert all(re.fullmatch(r"[0-9a-f]{64}\.(obj|off|ply|stl|glb)", n) for n in blob_names)


def test_container_runs_as_non_root():
    lines = [ln.strip() for ln in (REPO / "Dockerfile").read_text().splitlines()]
    final_stage = lines[max(i for i, ln in enumerate(lines) if ln.upper().startswith("FROM ")) :]
    users = [ln.split(None, 1)[1] for ln in final_stage if ln.upper().startswith("USER ")]
    assert users, "the runtime stage has no USER line"
    user = users[-1].split(":")[0]
    assert user not in ("0", "root")


def _sphere_obj(scale: float) -> bytes:
    import trimesh

    from tests.reliability.corpus import obj_text

    s = trimesh.creation.icosphere(subdivisions=2)
    return obj_text(s.vertices * [1.0, scale, 0.9], s.faces)


def _post(client, content: bytes, headers: dict | None = None):
    return client.post("/models", files={"file": ("door.obj", content)}, headers=headers or {})


WRONG_TOKENS = (
    "api-s3cret-kkkkkkkkkkkkkkkkkkkkk!",
    "api-s3cret-kkkkkkkkkkkkkkkkkkkkk api-s3cret-kkkkkkkkkkkkkkkkkkkkk",
    "api-s3cre",
    "API-S3CRET",
    "",
    "x" * 10_000,
    "admin-s3cret-kkkkkkkkkkkkkkkkkkk-",
)


def test_without_an_api_token_uploads_are_open_and_deletion_needs_the_admin_token(data_dir):
    with TestClient(
        create_app(make_settings(data_dir, admin_token="admin-s3cret-kkkkkkkkkkkkkkkkkkk"))
    ) as client:
        r = _post(client, _sphere_obj(1.11))
        assert r.status_code == 202, r.text
        model_id = r.json()["model_id"]
        for headers in (
            {},
            {"X-API-Token": "anything"},
            {"Authorization": "Bearer anything"},
            {"X-Admin-Token": "nope"},
        ):
            r = client.delete(f"/models/{model_id}", headers=headers)
            assert r.status_code == 401 and r.headers["www-authenticate"], headers
        assert client.get(f"/models/{model_id}").status_code == 200  # refused deletes delete nothing
        assert (
            client.delete(
                f"/models/{model_id}", headers={"Authorization": "Bearer admin-s3cret-kkkkkkkkkkkkkkkkkkk"}
            ).status_code
            == 204
        )


def test_with_an_api_token_writes_need_it_or_the_admin_token(data_dir):
    settings = make_settings(
        data_dir, admin_token="admin-s3cret-kkkkkkkkkkkkkkkkkkk", api_token="api-s3cret-kkkkkkkkkkkkkkkkkkkkk"
    )
    with TestClient(create_app(settings)) as client:
        before = client.get("/models").json()["count"]
        for i, wrong in enumerate(WRONG_TOKENS):
            for headers in (
                {"X-API-Token": wrong},
                {"Authorization": f"Bearer {wrong}"},
                {"X-Admin-Token": wrong},
                {},
            ):
                r = _post(client, _sphere_obj(1.2 + i / 100), headers)
                assert r.status_code == 401 and r.headers["www-authenticate"], (wrong[:20], headers)
        assert client.get("/models").json()["count"] == before  # nothing stored by a refused upload
        ids = []
        for i, headers in enumerate(
            (
                {"X-API-Token": "api-s3cret-kkkkkkkkkkkkkkkkkkkkk"},
                {"Authorization": "Bearer api-s3cret-kkkkkkkkkkkkkkkkkkkkk"},
                {"Authorization": "bearer api-s3cret-kkkkkkkkkkkkkkkkkkkkk"},
                {"X-Admin-Token": "admin-s3cret-kkkkkkkkkkkkkkkkkkk"},
                {"Authorization": "Bearer admin-s3cret-kkkkkkkkkkkkkkkkkkk"},
            )
        ):
            r = _post(client, _sphere_obj(1.5 + i / 100), headers)
            assert r.status_code == 202, (headers, r.text)
            ids.append(r.json()["model_id"])
        assert client.delete(f"/models/{ids[0]}").status_code == 401
        assert client.delete(f"/models/{ids[0]}", headers={"X-API-Token": "api-s3cre"}).status_code == 401
        assert (
            client.delete(
                f"/models/{ids[0]}", headers={"X-API-Token": "api-s3cret-kkkkkkkkkkkkkkkkkkkkk"}
            ).status_code
            == 204
        )
        assert (
            client.delete(
                f"/models/{ids[1]}", headers={"X-Admin-Token": "admin-s3cret-kkkkkkkkkkkkkkkkkkk"}
            ).status_code
            == 204
        )
        # reads stay open
        assert client.get(f"/models/{ids[2]}").status_code == 200
        assert client.get("/models").status_code == 200
