"""The Makefile a new user meets first (issue 14 items 1 and 9): `make -n` prints, runs nothing."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="no make on PATH")


def make(*args: str) -> str:
    # -o: treat the venv as up to date, so a dry run never plans an install
    run = subprocess.run(
        ["make", "-s", "-C", str(REPO), "-o", ".venv/bin/shapebag", *args],
        capture_output=True, text=True, timeout=30, check=True,
    )
    return run.stdout


def test_help_prints_the_values_not_the_variable_names() -> None:
    out = make("help", "PORT=9123")
    assert "127.0.0.1:9123" in out and "var/demo" in out and "var/data" in out
    assert "$(" not in out


def test_the_demo_and_the_users_data_live_apart() -> None:
    run, serve = make("-n", "run"), make("-n", "serve")
    assert "shapebag demo --data-dir var/demo" in run
    assert "shapebag serve --data-dir var/data" in serve and "var/demo" not in serve


def test_clean_keeps_data_and_clean_demo_removes_only_the_demo() -> None:
    assert "var/" not in make("-n", "clean")
    assert make("-n", "clean-demo").strip() == "rm -rf var/demo"


def test_the_first_install_says_what_it_is_doing() -> None:
    out = subprocess.run(
        ["make", "-n", "-C", str(REPO), "-W", "pyproject.toml", "install"],
        capture_output=True, text=True, timeout=30, check=True,
    ).stdout
    assert "installing shapebag" in out


def test_make_test_checks_for_chromium_first() -> None:
    out = make("-n", "test")
    assert out.index(".ci/chromium.sh") < out.index("pytest")
