"""One storage suite, two engines: every test taking `db` runs on SQLite and on PostgreSQL (the latter
skips, saying why, where no server can be started: see tests/pg_server.py)."""

from __future__ import annotations

import pytest

from app.storage.db import Database
from app.storage.engine import open_database
from tests.pg_server import db_url, pg_admin_url  # noqa: F401 (fixtures)


@pytest.fixture
def db(db_url, tmp_path) -> Database:  # noqa: F811
    database = open_database(tmp_path, db_url)
    database.migrate()
    database.migrate()  # idempotent
    return database
