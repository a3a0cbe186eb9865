"""A real Docker engine and a throw-away compose project for the deployment test.

The engine comes from ../shared/containers/docker-up.sh (Debian's docker.io + compose v2 + a local
Python base image, because no registry is reachable); the test skips only when no engine can be had.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared"  # /work/shared beside /work/main; ../shared in CI
DOCKER_UP = SHARED / "containers" / "docker-up.sh"
DOCKER_DOWN = SHARED / "containers" / "docker-down.sh"  # stops only the dockerd docker-up.sh started
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


def _engine_env(up_script: Path, env: dict[str, str]) -> dict[str, str]:
    """The environment docker-up.sh would export (`--env`: prints them, starts nothing)."""
    out = dict(env)
    try:
        printed = _run(["bash", str(up_script), "--env"], env, 30).stdout
    except subprocess.TimeoutExpired:
        return out
    for line in printed.splitlines():  # "export NAME=value" lines
        if line.startswith("export ") and "=" in line:
            name, value = line[len("export ") :].split("=", 1)
            out[name] = value
    return out


def _daemon_up(env: dict[str, str]) -> bool:
    if shutil.which("docker", path=env.get("PATH")) is None:
        return False
    try:
        return _run(["docker", "info"], env, 30).returncode == 0
    except subprocess.TimeoutExpired:
        return False


@contextlib.contextmanager
def engine(up_script: Path, down_script: Path, env: dict[str, str]) -> Iterator[dict[str, str]]:
    """A running engine's environment; stops it afterwards only if this call started it.

    `make test` must leave the machine as it found it: an engine that ran before the tests keeps running,
    one that docker-up.sh started for them is stopped by docker-down.sh (SHAPEBAG_KEEP_DOCKER=1 keeps it).
    """
    was_running = _daemon_up(_engine_env(up_script, env))
    try:
        up = _run(["bash", str(up_script)], env, 900)  # idempotent: seconds when warm, 2-3 minutes cold
    except subprocess.TimeoutExpired:
        pytest.skip(f"no Docker engine: {up_script} did not finish in 900 s")
    started = not was_running
    try:
        if up.returncode != 0:
            tail = (up.stdout + up.stderr).strip().splitlines()[-8:]
            pytest.skip(f"no Docker engine: {up_script} failed (exit {up.returncode}): " + " | ".join(tail))
        out = _engine_env(up_script, env)
        out.setdefault("BASE_IMAGE", LOCAL_BASE_IMAGE)
        yield out
    finally:
        if started and env.get("SHAPEBAG_KEEP_DOCKER") != "1" and down_script.is_file():
            _run(["bash", str(down_script)], env, 60)


@pytest.fixture(scope="session")
def docker_env() -> Iterator[dict[str, str]]:
    """Environment (DOCKER_HOST, DOCKER_CONFIG, BASE_IMAGE) of a running engine with compose v2."""
    env = dict(os.environ)
    if not DOCKER_UP.is_file():
        if not _engine_works(env):
            pytest.skip(f"no Docker engine: {DOCKER_UP} is missing and `docker info` / `docker compose` fail")
        yield env
        return
    with engine(DOCKER_UP, DOCKER_DOWN, env) as up:
        if not _engine_works(up):
            pytest.skip("no Docker engine: docker-up.sh ran; `docker info` or `docker compose version` fails")
        yield up


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Compose:
    """`docker compose -p <unique project>` over the repository's docker-compose.yml."""

    env: dict[str, str]
    project: str = field(default_factory=lambda: f"shapebag-test-{uuid.uuid4().hex[:8]}")
    file: str = "docker-compose.yml"  # docker-compose.scale.yml: tests/deploy/test_scale_compose.py

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.env['SHAPEBAG_PORT']}"

    def run(self, *args: str, timeout: float = 300, check: bool = True) -> subprocess.CompletedProcess[str]:
        cmd = ["docker", "compose", "-p", self.project, "-f", str(REPO / self.file), *args]
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
            str(REPO / self.file),
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


def wait_for(
    what: str,
    probe: Callable[[], Any],
    timeout: float,
    compose: Compose,
    every: float = 1.0,
    retry_on: tuple[type[BaseException], ...] = (httpx.HTTPError,),
) -> Any:
    """Poll `probe` until it returns something truthy; fail with `what`, the last value and the logs.
    An exception in `retry_on` (an api restarting) counts as "not yet" until the deadline."""
    deadline = time.monotonic() + timeout
    last: Any = None
    while time.monotonic() < deadline:
        try:
            last = probe()
        except retry_on as exc:
            last = f"{type(exc).__name__}: {exc}"
        else:
            if last:
                return last
        time.sleep(every)
    pytest.fail(f"timed out after {timeout:.0f} s waiting for {what}; last: {last!r}\n{compose.logs()}")
