"""Which database a process opens: SQLite in the data directory (the default), or PostgreSQL."""

from __future__ import annotations

from pathlib import Path

from app.storage.db import Database


def open_database(data_dir: Path, database_url: str = "") -> Database:
    """`database_url` empty: <data_dir>/shapebag.db; `postgresql://...`: that server (psycopg needed:
    `pip install 'shapebag[postgres]'`)."""
    if not database_url:
        return Database(data_dir / "shapebag.db")
    if not database_url.startswith(("postgresql://", "postgres://")):
        raise ValueError(f"unsupported database URL {database_url.split(':', 1)[0]!r}: use postgresql://...")
    from app.storage.postgres import PostgresDatabase  # psycopg only where PostgreSQL is used

    return PostgresDatabase(database_url)
