from __future__ import annotations

from app.storage.blobs import BlobStore, atomic_write, sha256_hex


def test_content_addressed_meshes_and_atomic_writes(tmp_path):
    blobs = BlobStore(tmp_path)
    digest, path = blobs.put_mesh(b"v 0 0 0\n", "obj")
    assert digest == sha256_hex(b"v 0 0 0\n") and path.read_bytes() == b"v 0 0 0\n"
    assert blobs.put_mesh(b"v 0 0 0\n", "obj") == (digest, path)
    atomic_write(blobs.description_path(7), b"x")
    atomic_write(blobs.thumbnail_path(7, 64), b"png")
    assert not list(tmp_path.rglob("*.tmp"))  # no temp files left behind
    blobs.delete_model_files(7, digest, "obj")
    assert not path.exists() and not blobs.description_path(7).exists()
    assert not blobs.thumbnail_path(7, 64).exists()
