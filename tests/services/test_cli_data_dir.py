"""The CLI's data directory: --data-dir > $SHAPEBAG_DATA_DIR > ./data, printed, and never an empty
database made up by a read-only command run from the wrong folder (issue 14 item 8)."""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh

from app.cli import main
from app.commands._common import DEFAULT_DATA_DIR, resolve_data_dir
from app.commands.demo import DEMO_DATA_DIR


@pytest.fixture
def query(tmp_path: Path) -> Path:
    path = tmp_path / "ball.obj"
    trimesh.creation.icosphere(subdivisions=1).export(path)
    return path


def test_flag_beats_environment_beats_default(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("SHAPEBAG_DATA_DIR", raising=False)
    assert resolve_data_dir(None) == ((tmp_path / DEFAULT_DATA_DIR).resolve(), "default data")
    monkeypatch.setenv("SHAPEBAG_DATA_DIR", str(tmp_path / "env"))
    assert resolve_data_dir(None) == ((tmp_path / "env").resolve(), "SHAPEBAG_DATA_DIR")
    assert resolve_data_dir(Path("flag")) == ((tmp_path / "flag").resolve(), "--data-dir")


def test_the_demo_never_takes_the_users_data_dir_from_the_environment(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SHAPEBAG_DATA_DIR", str(tmp_path / "mine"))
    path, _ = resolve_data_dir(None, DEMO_DATA_DIR, use_env=False)
    assert path == (tmp_path / "var" / "demo").resolve() and path != (tmp_path / "data").resolve()


@pytest.mark.parametrize("how", ["flag", "env", "default"])
def test_search_refuses_a_missing_data_dir_naming_it_and_creates_nothing(
    how: str, query: Path, tmp_path: Path, monkeypatch, capsys
) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    monkeypatch.delenv("SHAPEBAG_DATA_DIR", raising=False)
    missing = tmp_path / "nowhere" / "data"
    argv = ["search", str(query)]
    if how == "flag":
        argv += ["--data-dir", str(missing)]
    elif how == "env":
        monkeypatch.setenv("SHAPEBAG_DATA_DIR", str(missing))
    else:
        missing = elsewhere / "data"
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "no shapebag data" in err
    assert "no vocabulary" not in err
    assert not missing.exists()  # no empty database left behind


def test_vocabulary_show_refuses_a_missing_data_dir(tmp_path: Path, capsys) -> None:
    assert main(["vocabulary", "show", "--data-dir", str(tmp_path / "none")]) == 2
    assert str(tmp_path / "none") in capsys.readouterr().err
    assert not (tmp_path / "none").exists()


def test_the_data_dir_in_use_is_printed(tmp_path: Path, monkeypatch, capsys) -> None:
    from app.config import Settings
    from app.services.context import open_context

    open_context(Settings(data_dir=tmp_path / "d", dev_mode=True, default_vocabulary=None))  # a real one
    monkeypatch.setenv("SHAPEBAG_DATA_DIR", str(tmp_path / "d"))
    assert main(["vocabulary", "show"]) == 0
    captured = capsys.readouterr()
    assert f"data directory: {(tmp_path / 'd').resolve()} (SHAPEBAG_DATA_DIR)" in captured.err
    assert "no vocabulary yet" in captured.out
