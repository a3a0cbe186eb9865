"""One storage suite, two engines: every test taking `db` runs on SQLite and on PostgreSQL (the latter
skips, saying why, where no server can be started: see tests/pg_server.py)."""

from __future__ import annotations

import pytest

from app.storage.db import Database
from app.storage.engine import open_database
from tests import pg_server


@pytest.fixture(scope="session")
def pg_admin_url():
    try:
        with pg_server.server() as url:
            yield url
    except pg_server.Unavailable as exc:
        pytest.skip(f"PostgreSQL: {exc}")


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def db_url(request, tmp_path) -> str:
    """'' (SQLite in tmp_path) or the URL of a fresh PostgreSQL database."""
    if request.param == "sqlite":
        return ""
    return pg_server.fresh_database(request.getfixturevalue("pg_admin_url"))


@pytest.fixture
def db(db_url, tmp_path) -> Database:
    database = open_database(tmp_path, db_url)
    database.migrate()
    database.migrate()  # idempotent
    return database
