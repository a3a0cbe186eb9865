"""The service's CLI commands, in process: vocabulary fit, ingest (resumable), search, vocabulary show."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from app.cli import main
from app.core.vocabulary import Vocabulary


@pytest.fixture
def folder(tmp_path, corpus):
    """A labelled folder of 6 meshes (2 per class for 3 classes)."""
    root = tmp_path / "folder"
    rows = ["file,class"]
    picked = [f for i, f in enumerate(corpus.seeded) if i % 3 != 2][:6]
    for i, (path, label) in enumerate(picked):
        (root / label).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, root / label / f"{i}{path.suffix}")
        rows.append(f"{label}/{i}{path.suffix},{label}")
    (root / "labels.csv").write_text("\n".join(rows) + "\n")
    return root


@pytest.fixture(autouse=True)
def fast_describe(monkeypatch):
    for key, value in {"K": "40", "M": "20", "TARGET_VERTICES": "300"}.items():
        monkeypatch.setenv(f"SHAPEBAG_DESCRIBE__{key}", value)
    monkeypatch.setenv("SHAPEBAG_DEFAULT_VOCABULARY", "")


def test_vocabulary_fit_writes_a_loadable_vocabulary(folder, tmp_path, capsys):
    out = tmp_path / "vocab"
    assert main(["vocabulary", "fit", str(folder), "--out", str(out), "--size", "8", "--processes", "1"]) == 0
    vocab = Vocabulary.load(out)
    assert vocab.size == 8 and vocab.centers.shape == (8, 4) and np.isfinite(vocab.centers).all()
    meta = json.loads((out / "vocabulary.json").read_text())
    assert meta["meshes"] == 6 and meta["trained_on_descriptors"] > 8 and "vocabulary fit" in meta["command"]
    assert main(["vocabulary", "fit", str(folder), "--out", str(out)]) == 2  # immutable: refused


@pytest.mark.slow  # the CLI's describing processes, twice, then a vocabulary fit
def test_ingest_is_resumable_then_search_ranks_and_show_lists(folder, tmp_path, capsys, monkeypatch):
    data = tmp_path / "data"
    monkeypatch.setenv("SHAPEBAG_VOCABULARY_SIZE", "8")
    assert main(["ingest", str(folder), "--data-dir", str(data), "--processes", "1"]) == 0
    out = capsys.readouterr().out
    assert "6 new, 0 already stored" in out and "fitting one" in out
    assert main(["ingest", str(folder), "--data-dir", str(data), "--processes", "1"]) == 0
    assert "0 new, 6 already stored" in capsys.readouterr().out
    query = sorted(folder.rglob("0.*"))[0]
    assert main(["search", str(query), "--data-dir", str(data), "-k", "3"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["rank", "distance", "id", "label", "name"]
    first = lines[1].split()
    assert first[0] == "1" and float(first[1]) < 1e-3 and first[4].endswith("/0")
    assert main(["vocabulary", "show", "--data-dir", str(data)]) == 0
    assert "* v1: 8 words" in capsys.readouterr().out
    assert main(["search", str(tmp_path / "absent.obj"), "--data-dir", str(data)]) == 2
