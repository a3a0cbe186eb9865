"""A disk that fills (issue 34): under the free-space floor or past the quota, writes answer 507 with words
before SQLite fails; reads, searches and DELETE keep working, and a delete frees the model's files. The
free space is faked (services.space.free_bytes), never the real disk. Also: what a model stores, and the
lossless packing that cut a description from 357 KiB to ~210 KiB."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import StorageSettings
from app.core.packing import pack_float32, unpack_float32
from app.core.pipeline import ShapeDescription
from app.main import create_app
from app.services import space
from app.services.errors import InsufficientStorageError
from tests.conftest import make_settings, wait_for
from tests.reliability.corpus import valid_bytes
from tests.reliability.helpers import MULTIPART_HEADERS, multipart, snapshot

MB = 1 << 20


def test_packing_is_lossless_for_every_float32_bit_pattern():
    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2**32, size=(50, 17), dtype=np.uint64).astype(np.uint32)
    table = bits.view(np.float32)  # NaNs with payloads, infinities, denormals, negative zero
    for t in (table, table[:, :1], table[:0], np.float32([[np.nan, -0.0, np.inf, 1e-45]])):
        again = unpack_float32(pack_float32(t), t.shape)
        assert again.dtype == np.float32 and np.array_equal(again.view(np.uint32), t.view(np.uint32))
    with pytest.raises(ValueError, match="do not hold"):
        unpack_float32(pack_float32(table), (50, 16))


def test_packing_a_smooth_table_deflates_far_better_than_the_raw_floats():
    # an HKS-like table: per vertex, a smooth decay over 100 time scales
    rng = np.random.default_rng(1)
    t = np.geomspace(1e-3, 1.0, 100)
    rates = rng.uniform(0.5, 5.0, size=(1000, 1))
    table = (np.exp(-rates * t) / (1 + rates)).astype(np.float32)
    raw = len(zlib.compress(table.tobytes(), 6))
    packed = len(zlib.compress(pack_float32(table).tobytes(), 6))
    assert packed < 0.75 * raw, (packed, raw)


def test_a_format_1_description_still_loads_bit_for_bit(tmp_path):
    rng = np.random.default_rng(3)
    hks = rng.random((30, 8), dtype=np.float32)
    fields = dict(
        hks=hks,
        weights=np.full(30, 1 / 30, np.float32),
        keypoints=np.zeros(30, bool),
        eigenvalues=np.arange(5.0),
        input_vertices=np.int64(12),
        format=np.int64(1),
    )
    np.savez_compressed(tmp_path / "old.npz", **fields)
    old = ShapeDescription.load(tmp_path / "old.npz")
    assert np.array_equal(old.hks, hks) and old.input_vertices == 12
    old.save(tmp_path / "new.npz")
    assert np.array_equal(
        ShapeDescription.load(tmp_path / "new.npz").hks.view(np.uint32), hks.view(np.uint32)
    )


def test_check_room_keeps_the_floor_and_the_quota(tmp_path, monkeypatch):
    (tmp_path / "a").write_bytes(b"x" * (3 * MB))
    monkeypatch.setattr(space, "free_bytes", lambda path: 600 * MB)
    space.check_room(tmp_path, StorageSettings(min_free_mb=512), incoming=80 * MB)
    with pytest.raises(InsufficientStorageError, match="600 MB free, 512 MB kept free"):
        space.check_room(tmp_path, StorageSettings(min_free_mb=512), incoming=100 * MB)
    quota = StorageSettings(min_free_mb=0, quota_mb=4, measure_interval_s=0)
    space.check_room(tmp_path, quota, incoming=MB // 2)
    with pytest.raises(InsufficientStorageError, match="quota of 4 MB is used up"):
        space.check_room(tmp_path, quota, incoming=2 * MB)
    assert space.tree_bytes(tmp_path) == 3 * MB


@pytest.fixture
def client(data_dir, monkeypatch):
    settings = make_settings(data_dir)
    with TestClient(create_app(settings)) as c:
        wait_for(lambda: c.get("/readyz").status_code == 200, timeout_s=60)
        yield c


def test_a_full_disk_refuses_writes_with_507_and_keeps_reads_and_deletes(client, data_dir, monkeypatch):
    model = client.get("/models/1").json()
    stored = model["stored_bytes"]
    mesh = data_dir / "meshes" / model["sha256"][:2] / f"{model['sha256']}.{model['file_type']}"
    description = data_dir / "descriptions" / "1.npz"
    assert mesh.is_file() and description.is_file()
    assert stored >= mesh.stat().st_size + description.stat().st_size
    assert client.get("/models").json()["data"][0]["stored_bytes"] is None  # the list does not stat files

    monkeypatch.setattr(space, "free_bytes", lambda path: 100 * MB)  # under the 512 MB floor
    before = snapshot(data_dir)
    body = multipart("new.obj", valid_bytes("obj"))
    r = client.post("/models", content=body, headers=MULTIPART_HEADERS)
    assert r.status_code == 507 and r.json()["error"]["code"] == "insufficient_storage"
    assert "100 MB free" in r.json()["error"]["message"]
    token = {"X-Admin-Token": client.app.state.settings.admin_token}
    assert client.post("/admin/index/rebuild", headers=token).status_code == 507
    assert snapshot(data_dir) == before

    # reads and searches store nothing: they still answer
    assert client.get("/models").status_code == 200
    assert client.get("/models/1/mesh").status_code == 200
    assert client.post("/search", content=body, headers=MULTIPART_HEADERS).status_code == 200
    # and a delete frees the model's files
    assert client.delete("/models/1", headers=token).status_code == 204
    assert not description.exists()
    others = [m for m in client.get("/models?limit=500").json()["data"] if m["sha256"] == model["sha256"]]
    assert others or not mesh.exists()

    monkeypatch.setattr(space, "free_bytes", lambda path: 10_000 * MB)  # room again
    assert client.post("/models", content=body, headers=MULTIPART_HEADERS).status_code == 202


def test_sqlite_saying_the_disk_is_full_is_a_507_not_a_500(client, monkeypatch):
    import sqlite3

    from app.services import catalog

    def full(*args, **kwargs):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(catalog, "list_models", full)
    r = client.get("/models")
    assert r.status_code == 507 and r.json()["error"]["code"] == "insufficient_storage"
    assert r.headers["x-content-type-options"] == "nosniff"


def test_postgres_disk_full_is_a_507_too(client, monkeypatch):
    errors = pytest.importorskip("psycopg.errors")
    from app.services import catalog

    DiskFull = errors.DiskFull  # SQLSTATE 53100

    def full(*args, **kwargs):
        raise DiskFull("could not extend file: No space left on device")

    monkeypatch.setattr(catalog, "list_models", full)
    r = client.get("/models")
    assert r.status_code == 507 and r.json()["error"]["code"] == "insufficient_storage"
