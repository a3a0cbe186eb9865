"""Files under the data directory: uploaded meshes (content-addressed), descriptions, thumbnails.

Every write goes temp file -> fsync -> rename, so a reader never sees half a file.
"""

from __future__ import annotations

import hashlib
import os
import socket
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any


def writer_tag() -> str:
    """`<pid>@<host>`: who writes a temp file, so the start-up sweep can tell a dead writer's debris
    (remove now) from a live writer's file in another process or container (leave it)."""
    return f"{os.getpid()}@{socket.gethostname().replace('.', '_').replace('/', '_')}"


def atomic_write(path: Path, data: bytes | Callable[[Path], None]) -> Path:
    """Write bytes (or let `data(tmp_path)` write) to a temp file beside `path`, fsync, rename.

    The temp file is `.<name>.<pid>@<host>.<random>.tmp` (see writer_tag and services/sweep.py)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.{writer_tag()}.", suffix=".tmp", dir=path.parent)
    tmp = Path(tmp_name)
    try:
        if callable(data):
            os.close(fd)
            data(tmp)
        else:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


class BlobStore:
    """meshes/<ab>/<sha256>.<ext>, descriptions/<model id>.npz, thumbnails/<model id>-<size>.png"""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    def mesh_path(self, sha256: str, file_type: str) -> Path:
        return self.root / "meshes" / sha256[:2] / f"{sha256}.{file_type}"

    def put_mesh(self, data: bytes, file_type: str) -> tuple[str, Path]:
        digest = sha256_hex(data)
        path = self.mesh_path(digest, file_type)
        if not path.exists():
            atomic_write(path, data)
        return digest, path

    def description_path(self, model_id: int, part: int = 0) -> Path:
        """descriptions/<id>.npz, or <id>.o<part>.npz for an object row's (storage/objects.py)."""
        return self.root / "descriptions" / (f"{model_id}.npz" if part == 0 else f"{model_id}.o{part}.npz")

    def thumbnail_path(self, model_id: int, size: int) -> Path:
        return self.root / "thumbnails" / f"{model_id}-{size}.png"

    def view_path(self, model_id: int, name: str) -> Path:
        """views/<model id>.<name>: what a model needs to be viewed (its explain geometry), or the
        stored reason it could not be made (`<what>.failed`). A cache of this host's, like thumbnails."""
        return self.root / "views" / f"{model_id}.{name}"

    def delete_views(self, model_id: int) -> None:
        """The model's cached thumbnails, view files and stored view failures."""
        for thumb in (self.root / "thumbnails").glob(f"{model_id}-*.png"):
            thumb.unlink(missing_ok=True)
        for view in (self.root / "views").glob(f"{model_id}.*"):
            view.unlink(missing_ok=True)

    def ensure_mesh(self, data: bytes, sha256: str, file_type: str, conn: Any = None) -> Path:
        """The mesh file of `data`, written again if a delete removed it meanwhile (call under the
        database write lock: deletes remove mesh files under it, see hide_mesh). `conn`: that write
        transaction (the database backend stores the mesh in it; unused here)."""
        path = self.mesh_path(sha256, file_type)
        if not path.is_file():
            atomic_write(path, data)
        return path

    def put_description(self, model_id: int, write: Callable[[Path], None], part: int = 0) -> Path:
        """Cache a model's description (`part` > 0: one of its object rows'): `write(tmp_path)` writes it
        (ShapeDescription.save)."""
        return atomic_write(self.description_path(model_id, part), write)

    def object_description_paths(self, model_id: int) -> list[Path]:
        """This host's files of a model's object-row descriptions."""
        return sorted((self.root / "descriptions").glob(f"{model_id}.o*.npz"))

    def share_dir(self, directory: Path, conn: Any = None) -> None:
        """Let other hosts read the files of `directory` (under root; a vocabulary version): on a
        filesystem they already can. `conn`: the transaction that registers them."""

    def local_dir(self, directory: Path) -> Path:
        """`directory` with its shared files present on this host."""
        return directory

    def forget_dir(self, directory: Path) -> None:
        """The shared copy of a deleted directory goes (the caller removes the local one)."""

    def hide_mesh(self, sha256: str, file_type: str, conn: Any = None) -> Path | None:
        """Move a mesh file aside (a temp name the start-up sweep removes if we die) and return where;
        None if there was none. Called inside the delete's transaction (`conn`: the database backend
        deletes its copy in it); unlink it after the commit, or put it back with os.replace if the
        transaction fails."""
        # this store's own file, never a subclass's fetch-on-read (it would bring back what is deleted)
        path = BlobStore.mesh_path(self, sha256, file_type)
        trash = path.with_name(f".{path.name}.{writer_tag()}.deleted.tmp")  # one delete at a time: the lock
        try:
            os.replace(path, trash)
        except FileNotFoundError:
            return None
        return trash

    def model_bytes(self, model_id: int, sha256: str, file_type: str) -> int:
        """Bytes one model holds here: its mesh file, description, cached thumbnails and kept views (this
        host's files only: the database backend's fetch-on-read would write to answer)."""
        paths = [BlobStore.mesh_path(self, sha256, file_type), BlobStore.description_path(self, model_id)]
        paths += BlobStore.object_description_paths(self, model_id)
        paths += (self.root / "thumbnails").glob(f"{model_id}-*.png")
        paths += (self.root / "views").glob(f"{model_id}.*")
        total = 0
        for path in paths:
            try:
                total += path.stat().st_size
            except FileNotFoundError:
                continue
        return total

    def delete_model_files(
        self, model_id: int, sha256: str | None = None, file_type: str = "", conn: Any = None
    ) -> None:
        """Remove the description and cached thumbnails of one model, and its mesh when `sha256` is given
        (content is shared by identity: the caller decides whether another model still needs it).
        `conn`: the caller's write transaction, if inside one (the database backend deletes in it)."""
        if sha256 is not None:
            self.mesh_path(sha256, file_type).unlink(missing_ok=True)
        self.description_path(model_id).unlink(missing_ok=True)
        for path in self.object_description_paths(model_id):
            path.unlink(missing_ok=True)
        self.delete_views(model_id)
