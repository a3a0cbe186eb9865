"""The service's CLI commands, in process: vocabulary fit, ingest (resumable), search, vocabulary show."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from app.cli import main
from app.core.vocabulary import Vocabulary
from tests.conftest import make_settings


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


def test_ingest_takes_a_folder_without_labels_and_rows_without_a_class(folder, tmp_path, capsys, monkeypatch):
    from pathlib import Path

    from app.services.context import open_context
    from app.storage import models as models_repo

    monkeypatch.setenv("SHAPEBAG_VOCABULARY_SIZE", "8")
    rows = (folder / "labels.csv").read_text().splitlines()
    blank = rows[1].split(",")[0]  # the first mesh listed loses its class
    (folder / "labels.csv").write_text("\n".join([rows[0], f"{blank},", *rows[2:]]) + "\n")
    data = tmp_path / "data"
    assert main(["ingest", str(folder), "--data-dir", str(data), "--processes", "1"]) == 0
    assert "1 of 6 meshes have no label" in capsys.readouterr().out
    (folder / "labels.csv").unlink()
    plain = tmp_path / "plain"
    assert main(["ingest", str(folder), "--data-dir", str(plain), "--processes", "1"]) == 0
    out = capsys.readouterr().out
    assert "6 of 6 meshes have no label (no labels.csv)" in out and "6 new" in out
    for where, unlabelled in ((data, {blank}), (plain, {r.split(",")[0] for r in rows[1:]})):
        with open_context(make_settings(where)).db.read() as conn:
            models, _ = models_repo.page(conn, limit=100)
        assert len(models) == 6 and all(m.status == "ready" for m in models)
        names = {m.name for m in models if m.label is None}
        assert names == {Path(u).with_suffix("").as_posix() for u in unlabelled}, names


@pytest.mark.parametrize("command", ["serve", "demo"])
def test_a_busy_port_is_refused_before_anything_starts(command, tmp_path, capsys, monkeypatch):
    import socket

    import app.main
    from app.datasets import synthetic

    def must_not_run(*args, **kwargs):
        raise AssertionError("started although the port is taken")

    monkeypatch.setattr(app.main, "create_app", must_not_run)
    monkeypatch.setattr(synthetic, "generate", must_not_run)
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        argv = [command, "--data-dir", str(tmp_path / "d"), "--port", str(port)]
        code = main(argv + (["--dev"] if command == "serve" else []))
    err = capsys.readouterr().err
    assert code == 2 and f"cannot listen on 127.0.0.1:{port}" in err and "--port" in err
    assert not (tmp_path / "d" / "corpus").exists()


def test_a_free_port_passes_the_check():
    import socket

    from app.commands.serve import check_port_free

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    check_port_free("127.0.0.1", port)  # free again once closed: no error
