"""A throwaway PostgreSQL server for the tests, from Debian's packages (initdb + pg_ctl, a temp dir,
a free port). Opt-in: SHAPEBAG_TEST_POSTGRES=1 (`make test-scale`); SHAPEBAG_TEST_DATABASE_URL points
at an existing server instead (a database per test is created on it)."""

from __future__ import annotations

import glob
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from itertools import count

import pytest

OPT_IN = "SHAPEBAG_TEST_POSTGRES"
EXTERNAL = "SHAPEBAG_TEST_DATABASE_URL"
_names = count()


class Unavailable(RuntimeError):
    """Why the PostgreSQL cases skip."""


def _bindir() -> str:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/pg_ctl"))
    if found:
        return os.path.dirname(found[-1])
    pg_ctl = shutil.which("pg_ctl")
    if pg_ctl:
        return os.path.dirname(pg_ctl)
    raise Unavailable("no PostgreSQL binaries (apt-get install postgresql)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _as_server_user(cmd: list[str]) -> list[str]:
    # postgres refuses to run as root: Debian's `postgres` account runs it then
    if os.geteuid() != 0:
        return cmd
    if shutil.which("runuser") is None:
        raise Unavailable("running as root without runuser: cannot start postgres as a non-root user")
    return ["runuser", "-u", "postgres", "--", *cmd]


@contextmanager
def server() -> Iterator[str]:
    """Yields an admin URL (database `postgres`) of a fresh server; stops and deletes it afterwards."""
    if os.environ.get(EXTERNAL):
        yield os.environ[EXTERNAL]
        return
    if os.environ.get(OPT_IN) != "1":
        raise Unavailable(f"PostgreSQL cases run with {OPT_IN}=1 (make test-scale)")
    bindir = _bindir()
    root = tempfile.mkdtemp(prefix="shapebag-pg-")
    data = os.path.join(root, "data")
    if os.geteuid() == 0:
        shutil.chown(root, "postgres", "postgres")
    port = _free_port()
    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(_as_server_user(list(args)), capture_output=True, text=True, timeout=120)

    try:
        init = run(f"{bindir}/initdb", "-D", data, "-U", "shapebag", "--auth=trust", "-E", "UTF8", "-N")
        if init.returncode:
            raise Unavailable(f"initdb failed: {init.stderr.strip()[-300:]}")
        # durability off: a test server, thrown away (fsync costs seconds on a loaded disk)
        opts = f"-p {port} -k {root} -c listen_addresses=127.0.0.1 -F -c full_page_writes=off"
        opts += " -c max_connections=60"
        start = run(f"{bindir}/pg_ctl", "-D", data, "-l", f"{root}/log", "-o", opts, "-w", "-t60", "start")
        if start.returncode:
            raise Unavailable(f"pg_ctl start failed: {start.stderr.strip()[-300:]} {_tail(f'{root}/log')}")
        try:
            yield f"postgresql://shapebag@127.0.0.1:{port}/postgres"
        finally:
            run(f"{bindir}/pg_ctl", "-D", data, "-m", "immediate", "-w", "stop")
    finally:
        shutil.rmtree(root, ignore_errors=True)


def _tail(path: str) -> str:
    try:
        with open(path) as fh:
            return fh.read()[-300:]
    except OSError:
        return ""


def fresh_database(admin_url: str) -> str:
    """A new, empty database on the server: each test starts from nothing, as with a new SQLite file."""
    import psycopg

    name = f"t{os.getpid()}_{next(_names)}"
    with psycopg.connect(admin_url, autocommit=True) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{name}"')
        conn.execute(f'CREATE DATABASE "{name}" TEMPLATE template0')
    return admin_url.rsplit("/", 1)[0] + f"/{name}"


# Fixtures: import them into a conftest or test module (`from tests.pg_server import db_url, pg_admin_url`).


@pytest.fixture(scope="session")
def pg_admin_url() -> Iterator[str]:
    try:
        with server() as url:
            yield url
    except Unavailable as exc:
        pytest.skip(f"PostgreSQL: {exc}")


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
def db_url(request: pytest.FixtureRequest) -> str:
    """'' (SQLite in the data directory) or the URL of a fresh PostgreSQL database."""
    if request.param == "sqlite":
        return ""
    return fresh_database(request.getfixturevalue("pg_admin_url"))
