"""`make test` stops the Docker engine it started, and only that one (issue 14 item 9).

The scripts and the `docker` CLI are fakes on PATH: a state file says whether "the engine" runs.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.deploy.conftest import engine


@pytest.fixture
def fakes(tmp_path: Path) -> tuple[Path, Path, dict[str, str]]:
    state, bin_dir = tmp_path / "running", tmp_path / "bin"
    bin_dir.mkdir()
    docker = bin_dir / "docker"
    docker.write_text(f'#!/bin/sh\n[ "$1" = info ] && {{ [ -f {state} ]; exit $?; }}\nexit 0\n')
    docker.chmod(0o755)
    up = tmp_path / "up.sh"
    exports = 'echo "export DOCKER_HOST=unix:///fake"'
    up.write_text(f'[ "$1" = --env ] && {{ {exports}; exit 0; }}\ntouch {state}\n')
    down = tmp_path / "down.sh"
    down.write_text(f"rm -f {state}; touch {tmp_path / 'stopped'}\n")
    env = dict(os.environ, PATH=f"{bin_dir}:{os.environ['PATH']}")
    env.pop("SHAPEBAG_KEEP_DOCKER", None)
    return up, down, env


def test_an_engine_started_for_the_tests_is_stopped_after_them(fakes) -> None:
    up, down, env = fakes
    with engine(up, down, env) as started:
        assert started["DOCKER_HOST"] == "unix:///fake"
        assert (up.parent / "running").exists()
    assert not (up.parent / "running").exists() and (up.parent / "stopped").exists()


def test_an_engine_that_ran_before_keeps_running(fakes) -> None:
    up, down, env = fakes
    (up.parent / "running").touch()
    with engine(up, down, env):
        pass
    assert (up.parent / "running").exists() and not (up.parent / "stopped").exists()


def test_keep_docker_leaves_the_started_engine_up(fakes) -> None:
    up, down, env = fakes
    with engine(up, down, env | {"SHAPEBAG_KEEP_DOCKER": "1"}):
        pass
    assert (up.parent / "running").exists()
