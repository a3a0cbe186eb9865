"""The Makefile a new user meets first (issue 14 items 1 and 9): `make -n` prints, runs nothing."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="no make on PATH")


def make(*args: str, env: dict[str, str] | None = None) -> str:
    # -o: treat the venv as up to date, so a dry run never plans an install
    run = subprocess.run(
        ["make", "-s", "-C", str(REPO), "-o", ".venv/bin/shapebag", *args],
        capture_output=True, text=True, timeout=30, check=True, env=env or _env(),
    )
    return run.stdout


def _env(**extra: str) -> dict[str, str]:
    """This environment without the SHAPEBAG_* settings the Makefile reads, plus `extra`."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("SHAPEBAG_")}
    return env | extra


def test_help_prints_the_values_not_the_variable_names() -> None:
    out = make("help", "PORT=9123")
    assert "127.0.0.1:9123" in out and "var/demo" in out and "data/" in out
    assert "$(" not in out


def test_the_demo_and_the_users_data_live_apart() -> None:
    run, serve = make("-n", "run"), make("-n", "serve")
    assert "shapebag demo --data-dir var/demo" in run
    assert "shapebag serve --data-dir data --port 8000" in serve and "var/demo" not in serve


def test_serve_takes_the_data_dir_and_port_from_the_services_own_settings() -> None:
    serve = make("-n", "serve", env=_env(SHAPEBAG_DATA_DIR="/srv/shapes", SHAPEBAG_PORT="9001"))
    assert "shapebag serve --data-dir /srv/shapes --port 9001" in serve
    # a value on the command line still wins
    assert "--data-dir elsewhere" in make("-n", "serve", "DATA=elsewhere", env=_env(SHAPEBAG_DATA_DIR="/x"))


def test_clean_keeps_data_and_clean_demo_removes_only_the_demo() -> None:
    assert "var/" not in make("-n", "clean")
    assert make("-n", "clean-demo").strip() == "rm -rf var/demo"


def test_the_first_install_says_what_it_is_doing() -> None:
    out = subprocess.run(
        ["make", "-n", "-C", str(REPO), "-W", "pyproject.toml", "install"],
        capture_output=True, text=True, timeout=30, check=True,
    ).stdout
    assert "installing shapebag" in out


def test_make_test_is_the_quick_tier_in_parallel_and_test_all_the_rest_after_chromium() -> None:
    quick = make("-n", "test")
    assert "-n auto --dist loadscope" in quick and '-m "not slow and not docker"' in quick
    assert "chromium" not in quick
    everything = make("-n", "test-all")
    assert everything.index(".ci/chromium.sh") < everything.index("pytest")
    assert '-m "not slow and not docker"' in everything and '-m "slow or docker"' in everything


def test_a_target_that_needs_a_dataset_stops_naming_it(tmp_path: Path) -> None:
    for target in ("evaluate", "bench"):
        run = subprocess.run(
            ["make", "-s", "-C", str(REPO), "-o", ".venv/bin/shapebag", target],
            capture_output=True, text=True, timeout=30, env=_env(SHAPEBAG_DATASETS=str(tmp_path)),
        )
        assert run.returncode != 0 and "pytest" not in run.stdout
        assert f"dataset shrec11-simplified not found at {tmp_path}/shrec11-simplified" in run.stderr
        assert "SHAPEBAG_DATASETS" in run.stderr and "data/README.md" in run.stderr
