"""Blobs in the database (SHAPEBAG_BLOB_BACKEND=database): meshes and descriptions for hosts that share
no filesystem. The `blobs` table (bytea on PostgreSQL) holds the copy every host reads; the data
directory becomes a per-host cache that is filled on first use (paths stay what callers get, because
the describe and render subprocesses read files).

Guarantees kept from the filesystem store: a mesh enters and leaves the database in the same write
transaction as the model row that needs it (ensure_mesh / hide_mesh take the caller's `conn`), so an
upload and a delete of the same bytes stay linearisable and a rolled-back delete keeps its mesh; local
files are still written temp -> fsync -> rename. Meshes are content-addressed, description keys carry the
model id (never reused), so a cached file is never stale.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from app.storage.blobs import BlobStore, atomic_write, sha256_hex
from app.storage.db import Database, utcnow

# PostgreSQL's bytea holds up to 1 GB, and a value travels whole, in memory, on both sides: half of that
MAX_BLOB_BYTES = 512 * 1024 * 1024


_UNDER = "SELECT key FROM blobs WHERE substr(key, 1, ?) = ? ORDER BY key"


class BlobTooLargeError(ValueError):
    pass


def mesh_key(sha256: str, file_type: str) -> str:
    return f"meshes/{sha256}.{file_type}"


def description_key(model_id: int, part: int = 0) -> str:
    return f"descriptions/{model_id}.npz" if part == 0 else f"descriptions/{model_id}.o{part}.npz"


def object_descriptions_prefix(model_id: int) -> str:
    return f"descriptions/{model_id}.o"


def store(conn: Any, key: str, data: bytes, replace: bool) -> None:
    if len(data) > MAX_BLOB_BYTES:
        raise BlobTooLargeError(f"{key}: {len(data)} bytes, over the database blob limit of {MAX_BLOB_BYTES}")
    action = "UPDATE SET data = excluded.data, size_bytes = excluded.size_bytes" if replace else "NOTHING"
    conn.execute(
        "INSERT INTO blobs (key, data, size_bytes, created_at) VALUES (?, ?, ?, ?)"
        f" ON CONFLICT(key) DO {action}",
        (key, data, len(data), utcnow()),
    )


def load(conn: Any, key: str) -> bytes | None:
    row = conn.execute("SELECT data FROM blobs WHERE key = ?", (key,)).fetchone()
    return None if row is None else bytes(row[0])


class DatabaseBlobStore(BlobStore):
    """BlobStore's interface; the database holds the shared copy, `root` caches it on this host."""

    def __init__(self, root: Path, db: Database) -> None:
        super().__init__(root)
        self.db = db

    def _cached(self, path: Path, key: str) -> Path:
        """`path`, fetched from the database first when this host has no copy (absent there too: the
        path of a missing file, as the filesystem store would give)."""
        if not path.is_file():
            with self.db.read() as conn:
                data = load(conn, key)
            if data is not None:
                atomic_write(path, data)
        return path

    def mesh_path(self, sha256: str, file_type: str) -> Path:
        return self._cached(super().mesh_path(sha256, file_type), mesh_key(sha256, file_type))

    def description_path(self, model_id: int, part: int = 0) -> Path:
        return self._cached(super().description_path(model_id, part), description_key(model_id, part))

    def put_mesh(self, data: bytes, file_type: str) -> tuple[str, Path]:
        # this host's copy only: the shared one is written by ensure_mesh, inside the model's transaction
        digest = sha256_hex(data)
        path = super().mesh_path(digest, file_type)
        if not path.exists():
            atomic_write(path, data)
        return digest, path

    def ensure_mesh(self, data: bytes, sha256: str, file_type: str, conn: Any = None) -> Path:
        if conn is None:  # outside a caller's transaction: a short one of our own
            with self.db.queue() as own:
                store(own, mesh_key(sha256, file_type), data, replace=False)
        else:
            store(conn, mesh_key(sha256, file_type), data, replace=False)
        path = super().mesh_path(sha256, file_type)
        if not path.is_file():
            atomic_write(path, data)
        return path

    def put_description(self, model_id: int, write: Callable[[Path], None], part: int = 0) -> Path:
        path = atomic_write(super().description_path(model_id, part), write)
        with self.db.queue() as conn:
            store(conn, description_key(model_id, part), path.read_bytes(), replace=True)
        return path

    def hide_mesh(self, sha256: str, file_type: str, conn: Any = None) -> Path | None:
        """Delete the shared copy in the caller's transaction (a rollback brings it back) and move this
        host's copy aside as the filesystem store does."""
        key = mesh_key(sha256, file_type)
        if conn is None:
            with self.db.queue() as own:
                self._delete(own, [key])
        else:
            self._delete(conn, [key])
        return super().hide_mesh(sha256, file_type)  # this host's cached copy, moved aside alike

    def delete_model_files(
        self, model_id: int, sha256: str | None = None, file_type: str = "", conn: Any = None
    ) -> None:
        keys = [description_key(model_id)] + ([mesh_key(sha256, file_type)] if sha256 is not None else [])
        prefix = object_descriptions_prefix(model_id)
        if conn is None:
            with self.db.queue() as own:
                self._delete(own, keys)
                own.execute("DELETE FROM blobs WHERE substr(key, 1, ?) = ?", (len(prefix), prefix))
        else:  # inside the caller's write: a second transaction would wait on it (SQLite's one writer)
            self._delete(conn, keys)
            conn.execute("DELETE FROM blobs WHERE substr(key, 1, ?) = ?", (len(prefix), prefix))
        if sha256 is not None:
            super().mesh_path(sha256, file_type).unlink(missing_ok=True)
        super().description_path(model_id).unlink(missing_ok=True)
        for path in super().object_description_paths(model_id):
            path.unlink(missing_ok=True)
        self.delete_views(model_id)

    def _prefix(self, directory: Path) -> str:
        return directory.resolve().relative_to(self.root.resolve()).as_posix() + "/"

    def share_dir(self, directory: Path, conn: Any = None) -> None:
        files = [p for p in sorted(directory.rglob("*")) if p.is_file()]
        prefix = self._prefix(directory)
        if conn is None:
            with self.db.queue() as own:
                self.share_dir(directory, own)
            return
        for path in files:
            key = prefix + path.relative_to(directory).as_posix()
            store(conn, key, path.read_bytes(), replace=True)

    def local_dir(self, directory: Path) -> Path:
        prefix = self._prefix(directory)
        with self.db.read() as conn:  # substr, not LIKE: '_' in a name is no wildcard
            keys = [r[0] for r in conn.execute(_UNDER, (len(prefix), prefix))]
        for key in keys:
            self._cached(self.root / key, key)
        return directory

    def forget_dir(self, directory: Path) -> None:
        prefix = self._prefix(directory)
        with self.db.queue() as conn:
            conn.execute("DELETE FROM blobs WHERE substr(key, 1, ?) = ?", (len(prefix), prefix))

    @staticmethod
    def _delete(conn: Any, keys: list[str]) -> None:
        for key in keys:
            conn.execute("DELETE FROM blobs WHERE key = ?", (key,))

    def stored_keys(self) -> list[str]:
        with self.db.read() as conn:
            return [r[0] for r in conn.execute("SELECT key FROM blobs ORDER BY key")]
