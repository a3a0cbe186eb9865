"""A real Docker engine and a throw-away compose project for the deployment test.

The engine comes from ../shared/containers/docker-up.sh (Debian's docker.io + compose v2 + a local
Python base image, because no registry is reachable); the test skips only when no engine can be had.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared"  # /work/shared beside /work/main; ../shared in CI
DOCKER_UP = SHARED / "containers" / "docker-up.sh"
DATASET = SHARED / "datasets" / "shrec11-simplified"
LOCAL_BASE_IMAGE = "localhost/debian-python:bookworm"
TEST_IMAGE = "shapebag:compose-test"  # removed by the final `down --rmi all`; the build cache stays


def _run(cmd: list[str], env: dict[str, str], timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, check=False)


def _engine_works(env: dict[str, str]) -> bool:
    if shutil.which("docker", path=env.get("PATH")) is None:
        return False
    try:
        ok = _run(["docker", "info"], env, 30).returncode == 0
        return ok and _run(["docker", "compose", "version"], env, 30).returncode == 0
    except subprocess.TimeoutExpired:
        return False


@pytest.fixture(scope="session")
def docker_env() -> dict[str, str]:
    """Environment (DOCKER_HOST, DOCKER_CONFIG, BASE_IMAGE) of a running engine with compose v2."""
    env = dict(os.environ)
    if DOCKER_UP.is_file():
        # idempotent: a few seconds when the engine already runs, 2-3 minutes cold
        try:
            up = _run(["bash", str(DOCKER_UP)], env, 900)
        except subprocess.TimeoutExpired:
            pytest.skip(f"no Docker engine: {DOCKER_UP} did not finish in 900 s")
        if up.returncode != 0:
            tail = (up.stdout + up.stderr).strip().splitlines()[-8:]
            pytest.skip(f"no Docker engine: {DOCKER_UP} failed (exit {up.returncode}): " + " | ".join(tail))
        for line in up.stdout.splitlines():  # "export NAME=value" lines
            if line.startswith("export ") and "=" in line:
                name, value = line[len("export ") :].split("=", 1)
                env[name] = value
        env.setdefault("BASE_IMAGE", LOCAL_BASE_IMAGE)
    elif not _engine_works(env):
        pytest.skip(f"no Docker engine: {DOCKER_UP} is missing and `docker info` / `docker compose` fail")
    if not _engine_works(env):
        pytest.skip("no Docker engine: docker-up.sh ran but `docker info` or `docker compose version` fails")
    return env


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Compose:
    """`docker compose -p <unique project>` over the repository's docker-compose.yml."""

    env: dict[str, str]
    project: str = field(default_factory=lambda: f"shapebag-test-{uuid.uuid4().hex[:8]}")

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.env['SHAPEBAG_PORT']}"

    def run(self, *args: str, timeout: float = 300, check: bool = True) -> subprocess.CompletedProcess[str]:
        cmd = ["docker", "compose", "-p", self.project, "-f", str(REPO / "docker-compose.yml"), *args]
        try:
            result = _run(cmd, self.env, timeout)
        except subprocess.TimeoutExpired as exc:
            raise AssertionError(f"`{' '.join(cmd[3:])}` ran past {timeout:.0f} s\n{self.logs()}") from exc
        if check and result.returncode != 0:
            raise AssertionError(
                f"`{' '.join(cmd[3:])}` failed (exit {result.returncode}):\n{result.stdout}\n{result.stderr}"
                f"\n{self.logs()}"
            )
        return result

    def logs(self, tail: int = 80) -> str:
        cmd = [
            "docker",
            "compose",
            "-p",
            self.project,
            "-f",
            str(REPO / "docker-compose.yml"),
            "logs",
            "--no-color",
            "--tail",
            str(tail),
        ]
        try:
            out = _run(cmd, self.env, 60)
        except subprocess.TimeoutExpired:
            return "(docker compose logs timed out)"
        return f"---- docker compose logs (last {tail} lines per service) ----\n{out.stdout}{out.stderr}"

    def volumes(self) -> list[str]:
        out = _run(
            ["docker", "volume", "ls", "-q", "--filter", f"label=com.docker.compose.project={self.project}"],
            self.env,
            60,
        )
        return out.stdout.split()


@pytest.fixture
def stack(docker_env: dict[str, str]) -> Iterator[Compose]:
    """A fresh compose project on a free loopback port; always ends with `down -v` (volume and image gone)."""
    env = dict(docker_env)
    env.update(
        SHAPEBAG_ADMIN_TOKEN=uuid.uuid4().hex,
        SHAPEBAG_BIND="127.0.0.1",
        SHAPEBAG_PORT=str(free_port()),
        SHAPEBAG_IMAGE=TEST_IMAGE,
        SHAPEBAG_API_WORKERS="0",
    )
    compose = Compose(env)
    try:
        yield compose
    finally:
        compose.run(
            "down", "-v", "--remove-orphans", "--rmi", "all", "--timeout", "20", timeout=180, check=False
        )
        left = compose.volumes()
        assert not left, f"`docker compose down -v` left volumes behind: {left}"
