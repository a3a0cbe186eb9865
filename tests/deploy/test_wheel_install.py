"""`pip install` of the wheel (not editable) ships the default vocabulary: a fresh venv, an empty data
directory, no model ingested, and the shipped vocabulary is the active one at once (no fitting).

The wheel is built from a copy of the sources (the shared tree stays untouched) with pip's build isolation
(the build backend comes from the package index or pip's cache); the fresh venv gets the wheel alone, and
finds the dependencies through a path entry to this test's own site-packages, appended after its own
(so `app` can only come from the wheel).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SHIPPED = REPO / "app" / "data" / "vocabulary" / "default" / "vocabulary.json"

PROBE = """
import json, sys
from pathlib import Path
from fastapi.testclient import TestClient
import app
from app.config import Settings
from app.main import create_app

token = "wheel-test-kkkkkkkkkkkkkkkkkkkkk"
settings = Settings(data_dir=Path(sys.argv[1]), dev_mode=True, admin_token=token, workers=0, warm_up=False)
with TestClient(create_app(settings)) as client:
    r = client.get("/admin/vocabulary", headers={"X-Admin-Token": token})
    print(json.dumps({"app": app.__file__, "shipped": str(settings.default_vocabulary),
                      "status": r.status_code, "vocabulary": r.json()}))
"""

pytestmark = pytest.mark.slow


def _run(cmd: list[str], cwd: Path, timeout: float = 300) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SHAPEBAG_") and k != "PYTHONPATH"}
    done = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"{' '.join(cmd)}\n{done.stdout}\n{done.stderr}"
    return done.stdout


@pytest.fixture(scope="module")
def venv_python(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("wheel")
    src = root / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, src / name)
    shutil.copytree(REPO / "app", src / "app", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    _run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q", "-w", str(root / "dist")], root)
    (wheel,) = (root / "dist").glob("shapebag-*.whl")
    venv = root / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], root)
    python = venv / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps", "--no-index",
          str(wheel)], root)
    purelib = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], root)
    # the dependencies: this interpreter's site-packages, after the venv's own (a plain path: its .pth
    # files, the editable install's among them, are not processed)
    (Path(purelib.strip()) / "zz_test_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return python


def test_the_wheel_serves_the_shipped_vocabulary_on_an_empty_data_dir(venv_python, tmp_path):
    assert SHIPPED.is_file(), "the shipped vocabulary is missing from app/data/vocabulary/default"
    shipped = json.loads(SHIPPED.read_text())
    out = _run([str(venv_python), "-c", PROBE, str(tmp_path / "data")], cwd=tmp_path)
    got = json.loads(out.strip().splitlines()[-1])
    venv = venv_python.parent.parent
    assert Path(got["app"]).is_relative_to(venv), f"imported app from {got['app']}, not from the wheel"
    assert Path(got["shipped"]).is_relative_to(venv) and (Path(got["shipped"]) / "centers.npy").is_file()
    assert got["status"] == 200, got
    vocab = got["vocabulary"]
    assert vocab["id"] == 1 and vocab["words"] == shipped["size"] and vocab["indexed_models"] == 0
    meta = vocab["metadata"]
    assert meta["created_at"] == shipped["created_at"] and meta["source"] == shipped["source"]
    assert meta["fusion"] == shipped["fusion"]  # served fused, with the scales fixed at vocabulary time
