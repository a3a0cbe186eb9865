"""The database blob backend, on SQLite and PostgreSQL: two hosts with separate data directories share
meshes and descriptions through the database alone; a mesh enters and leaves with its transaction."""

from __future__ import annotations

import pytest

from app.storage import blobs_db
from app.storage.blobs import sha256_hex
from app.storage.blobs_db import BlobTooLargeError, DatabaseBlobStore

MESH = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


@pytest.fixture
def hosts(db, tmp_path) -> tuple[DatabaseBlobStore, DatabaseBlobStore]:
    return DatabaseBlobStore(tmp_path / "host-a", db), DatabaseBlobStore(tmp_path / "host-b", db)


def test_another_host_reads_what_one_host_stored(db, hosts):
    a, b = hosts
    digest, local = a.put_mesh(MESH, "obj")
    assert local.read_bytes() == MESH and not b.mesh_path(digest, "obj").exists()  # not shared yet
    with db.write() as conn:
        a.ensure_mesh(MESH, digest, "obj", conn)
    assert b.mesh_path(digest, "obj").read_bytes() == MESH  # fetched into host b's cache
    a.put_description(7, lambda tmp: tmp.write_bytes(b"npz-bytes"))
    assert b.description_path(7).read_bytes() == b"npz-bytes"
    a.put_description(7, lambda tmp: tmp.write_bytes(b"npz-bytes-2"))  # a rewrite replaces the copy
    assert DatabaseBlobStore(b.root.parent / "host-c", db).description_path(7).read_bytes() == b"npz-bytes-2"
    assert not list(b.root.rglob("*.tmp"))
    assert not b.description_path(8).exists()  # nothing anywhere: a missing path, as on a filesystem


def test_a_mesh_enters_and_leaves_with_its_transaction(db, hosts):
    a, b = hosts
    digest = sha256_hex(MESH)
    with pytest.raises(RuntimeError), db.write() as conn:
        a.ensure_mesh(MESH, digest, "obj", conn)
        raise RuntimeError("the upload's transaction fails")
    assert a.stored_keys() == []  # rolled back with it
    with db.write() as conn:
        a.ensure_mesh(MESH, digest, "obj", conn)
    with pytest.raises(RuntimeError), db.write() as conn:
        assert a.hide_mesh(digest, "obj", conn) is not None  # host a's copy moved aside
        raise RuntimeError("the delete's transaction fails")
    assert a.stored_keys() == [blobs_db.mesh_key(digest, "obj")]  # the shared copy came back
    with db.write() as conn:
        a.hide_mesh(digest, "obj", conn)
    assert a.stored_keys() == []
    assert not DatabaseBlobStore(b.root.parent / "host-c", db).mesh_path(digest, "obj").exists()


def test_delete_model_files_and_the_size_limit(db, hosts, monkeypatch):
    a, b = hosts
    digest, _ = a.put_mesh(MESH, "obj")
    a.ensure_mesh(MESH, digest, "obj")  # no caller transaction: its own
    a.put_description(3, lambda tmp: tmp.write_bytes(b"d"))
    assert b.description_path(3).is_file()
    a.put_description(4, lambda tmp: tmp.write_bytes(b"e"))
    with db.write() as conn:  # inside a write it deletes in that transaction (no second writer to wait on)
        a.delete_model_files(4, conn=conn)
    a.delete_model_files(3, digest, "obj")
    assert a.stored_keys() == [] and not a.description_path(3).exists()
    assert not a.mesh_path(digest, "obj").exists()
    monkeypatch.setattr(blobs_db, "MAX_BLOB_BYTES", len(MESH) - 1)
    with pytest.raises(BlobTooLargeError, match="over the database blob limit"), db.write() as conn:
        a.ensure_mesh(MESH, digest, "obj", conn)
    assert a.stored_keys() == []


def test_a_directory_shared_in_a_transaction_reaches_another_host(db, hosts):
    a, b = hosts
    version = a.root / "vocabularies" / "3"
    (version / "sub").mkdir(parents=True)
    (version / "words.npy").write_bytes(b"w")
    (version / "sub" / "meta_1.json").write_bytes(b"{}")
    with pytest.raises(RuntimeError), db.write() as conn:
        a.share_dir(version, conn)
        raise RuntimeError("the registration fails")
    assert a.stored_keys() == []
    other = a.root / "vocabularies" / "30"  # shares a name prefix, not the directory
    other.mkdir()
    (other / "words.npy").write_bytes(b"30")
    with db.write() as conn:
        a.share_dir(version, conn)
        a.share_dir(other, conn)
    there = b.local_dir(b.root / "vocabularies" / "3")
    assert (there / "words.npy").read_bytes() == b"w"
    assert (there / "sub" / "meta_1.json").read_bytes() == b"{}"
    assert not (b.root / "vocabularies" / "30").exists()
    a.forget_dir(version)
    assert a.stored_keys() == ["vocabularies/30/words.npy"]
