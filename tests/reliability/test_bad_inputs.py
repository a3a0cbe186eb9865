"""Every input of the bad-input corpus gets a 4xx with a readable message from POST /models and POST /search
(and, for bad content, from the web page's preview), a one-line error (exit 2) from `shapebag search FILE`,
and leaves the store exactly as it was."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys

import pytest
from fastapi.testclient import TestClient

from app.cli import main as cli_main
from app.core.mesh import InvalidMeshError
from app.main import create_app
from app.services.mesh_policy import load_upload
from tests.conftest import make_settings, wait_for
from tests.reliability.corpus import MAX_VERTICES, build, gzip_body_bomb, obj_text
from tests.reliability.helpers import MULTIPART_HEADERS, multipart, snapshot

CASES = build()


@pytest.fixture(scope="module")
def served(seeded_dir, tmp_path_factory):
    data = shutil.copytree(seeded_dir, tmp_path_factory.mktemp("bad") / "data")
    settings = make_settings(data, max_vertices=MAX_VERTICES, max_upload_bytes=2_000_000)
    with TestClient(create_app(settings)) as client:
        wait_for(lambda: client.get("/readyz").status_code == 200, timeout_s=60)
        yield client, data


# what leaks from a bug rather than a decision: exception class names, Python's own wording
UNREADABLE = re.compile(
    r"Traceback|internal|\b[A-Z]\w*(Error|Exception)\b|NoneType|not subscriptable|has no attribute"
    r"|setting an array element|out of bounds for axis|not enough values to unpack|unhashable type"
    r"|invalid literal for|object is not|<[a-z_.]+ object at 0x"
)


def _readable(body: dict) -> str:
    message = body["error"]["message"]
    assert 10 <= len(message) <= 400, message
    assert not UNREADABLE.search(message), f"not a message for a user: {message!r}"
    return message


def test_the_corpus_is_big_and_each_file_is_refused_by_the_loader():
    assert len(CASES) >= 40 and len({c.case for c in CASES}) == len(CASES)
    accepted = []
    for case in (c for c in CASES if c.file_level and "." in c.filename):
        ext = case.filename.rsplit(".", 1)[1]
        try:
            load_upload(case.content, ext, MAX_VERTICES)
            accepted.append(case.case)
        except InvalidMeshError:
            pass
    assert accepted == [], f"accepted by load_upload: {accepted}"


def test_every_bad_input_gets_a_4xx_and_changes_nothing(served):
    client, data = served
    good = obj_text(*_good_mesh())
    before = snapshot(data)
    indexed = client.get("/readyz").json()["checks"]["indexed_models"]
    wrong = []
    for case in CASES:
        body = multipart(case.filename, case.content, case.fields)
        # the web page's preview stores nothing and ignores names: only bad content concerns it
        for route in ("/models", "/search", "/web/preview.png")[: 3 if case.file_level else 2]:
            r = client.post(route, content=body, headers=MULTIPART_HEADERS)
            if not 400 <= r.status_code < 500 or "error" not in r.json():
                wrong.append(f"{route} {case.case}: {r.status_code} {r.text[:200]}")
                continue
            try:
                _readable(r.json())
            except AssertionError as exc:
                wrong.append(f"{route} {case.case}: unclear message {exc}")
    assert not wrong, "\n".join(wrong)

    # a gzip bomb as Content-Encoding is refused before anything reads (let alone inflates) it
    bomb = gzip_body_bomb(256 << 20)
    assert len(bomb) < 1_000_000
    for route in ("/models", "/search"):
        r = client.post(route, content=bomb, headers={**MULTIPART_HEADERS, "content-encoding": "gzip"})
        assert r.status_code == 415 and "compressed" in _readable(r.json())

    after = snapshot(data)
    assert after == before
    assert client.get("/readyz").json()["checks"]["indexed_models"] == indexed
    # still serving: a good query answers, a good upload is accepted
    r = client.post("/search", content=multipart("good.obj", good), headers=MULTIPART_HEADERS)
    assert r.status_code == 200 and r.json()["count"] > 0


def _good_mesh():
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=2)
    return s.vertices * [1.0, 1.3, 0.8], s.faces


def test_error_messages_say_what_is_wrong(served):
    client, _ = served
    by_case = {c.case: c for c in CASES}
    expect = {
        "empty": "empty",
        "nan-obj": "NaN",
        "face-missing-vertex": "does not exist",
        "point-cloud-obj": "point cloud",
        "one-triangle": "too few",
        "zero-area-collinear": "zero total area",
        "non-manifold-fan": "non-manifold",
        "triangle-soup": "triangle soup",
        "over-vertex-limit": f"limit of {MAX_VERTICES}",
        "wrong-extension": "unsupported mesh format",
        "path-traversal": "not a path",
        "enormous-label": "longer than",
        "bidi-override-label": "U+202E",
        "invalid-utf8-label": "UTF-8",
        "nul-in-filename": "control character",
        "face-index-zero-0": "from 1",
        "filename-256-chars": "longer than 255",
        "private-use-in-label": "private-use",
        "format-zwsp-in-name": "U+200B",
        "control-in-filename": "control character",
    }
    for name, words in expect.items():
        case = by_case[name]
        r = client.post(
            "/models", content=multipart(case.filename, case.content, case.fields), headers=MULTIPART_HEADERS
        )
        assert words in _readable(r.json()), (name, r.json())


def test_cli_search_refuses_each_bad_file_with_one_line(served, tmp_path, monkeypatch, capsys):
    _, data = served
    monkeypatch.setenv("SHAPEBAG_MAX_VERTICES", str(MAX_VERTICES))
    file_cases = [c for c in CASES if c.file_level]
    wrong = []
    for i, case in enumerate(file_cases):
        path = tmp_path / str(i) / case.filename
        path.parent.mkdir()
        path.write_bytes(case.content)
        code = cli_main(["search", str(path), "--data-dir", str(data)])
        # less the CLI's informational "data directory: ..." line (which directory it resolved)
        err = "\n".join(
            ln for ln in capsys.readouterr().err.strip().splitlines() if not ln.startswith("data directory: ")
        )
        if code != 2 or len(err.splitlines()) != 1 or not err.startswith("shapebag search: error: "):
            wrong.append(f"{case.case}: exit {code}, stderr {err[:300]!r}")
    assert not wrong, "\n".join(wrong)
    # and once as a real process: the exit status and the single stderr line
    bad = tmp_path / "0" / file_cases[0].filename
    p = subprocess.run(
        [sys.executable, "-m", "app.cli", "search", str(bad), "--data-dir", str(data)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = [ln for ln in p.stderr.strip().splitlines() if not ln.startswith("data directory: ")]
    assert p.returncode == 2 and len(lines) == 1, p.stderr
