"""What every process (API, worker, CLI) opens first: settings, the database and the blob store."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from app.config import Settings
from app.index import FILE_NAMES
from app.storage.blobs import BlobStore
from app.storage.blobs_db import DatabaseBlobStore
from app.storage.db import Database
from app.storage.engine import open_database


@dataclass(frozen=True)
class ServiceContext:
    settings: Settings
    db: Database
    blobs: BlobStore

    @property
    def data_dir(self) -> Path:
        return self.settings.data_dir

    def vocabulary_dir(self, vocabulary_id: int) -> Path:
        return self.data_dir / "vocabularies" / str(vocabulary_id)

    def index_path(self, vocabulary_id: int) -> Path:
        return self.vocabulary_dir(vocabulary_id) / FILE_NAMES[self.settings.index_backend]


def open_context(settings: Settings) -> ServiceContext:
    """Create the data directory and migrate the database (idempotent, safe from any process)."""
    data_dir = Path(settings.data_dir).resolve()
    settings = settings.model_copy(update={"data_dir": data_dir})
    data_dir.mkdir(parents=True, exist_ok=True)
    db = open_database(data_dir, settings.database_url)
    db.migrate()
    blobs = DatabaseBlobStore(data_dir, db) if settings.blob_backend == "database" else BlobStore(data_dir)
    return ServiceContext(settings=settings, db=db, blobs=blobs)
