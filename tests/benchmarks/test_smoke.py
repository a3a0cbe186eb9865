"""The benchmark scripts run end to end in a tiny mode and print their tables (no timing assertions)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import common, describe, quality, realbof, search, service, throughput
from tests.conftest import needs_dataset as _needs

needs_dataset = _needs("shrec11-simplified")


@pytest.fixture(autouse=True)
def _results_in_tmp(tmp_path, monkeypatch):
    monkeypatch.setattr(common, "RESULTS_DIR", tmp_path / "results")
    monkeypatch.setattr(realbof, "CACHE", tmp_path / "cache")
    monkeypatch.setattr(quality, "CACHE", tmp_path / "cache")


def _json(tmp_path, name: str) -> dict:
    doc = json.loads((tmp_path / "results" / f"{name}.json").read_text())
    assert doc["benchmark"] == name and doc["machine"]["cpus"] >= 1
    return doc


def test_table_aligns_columns_and_formats_numbers():
    text = common.table([{"a": 1, "b": 0.00012345}, {"a": 22, "b": 1234.5}], title="t")
    lines = text.splitlines()
    assert lines[0] == "t" and len({len(line) for line in lines[1:]}) == 1
    assert "1.2e-04" in text and "1234" in text and "22" in text


def test_recall_at_counts_the_overlap():
    got = np.array([[1, 2, 3], [4, 5, 6]])
    want = np.array([[3, 2, 9], [7, 8, 9]])
    assert search.recall_at(got, want) == pytest.approx((2 / 3 + 0) / 2)


def test_augmented_vectors_look_like_bof_vectors():
    rng = np.random.default_rng(0)
    real = rng.dirichlet(np.full(64, 0.2), size=30).astype(np.float32)
    fake = realbof.augment(real, 500, seed=1)
    assert fake.shape == (500, 64) and fake.dtype == np.float32
    assert (fake >= 0).all() and np.allclose(fake.sum(axis=1), 1.0, atol=1e-5)
    nearest = np.abs(fake[:, None, :] - real[None]).sum(axis=2).min(axis=1)  # L1 to the closest real one
    between = np.abs(real[:, None, :] - real[None]).sum(axis=2)[np.triu_indices(30, 1)]
    assert np.median(nearest) < np.median(between)  # near a real shape, not uniform noise


@pytest.mark.slow
@needs_dataset
def test_describe_benchmark_prints_ours_and_plain(tmp_path, capsys):
    assert describe.main(["--tiny"]) == 0
    out = capsys.readouterr().out
    assert "ratio" in out and "plain" in out and "ours" in out
    rows = _json(tmp_path, "describe-tiny")["rows"]
    assert {r["pipeline"] for r in rows} == {"ours", "plain"}
    ours = [r for r in rows if r["pipeline"] == "ours"]
    assert all(r["ratio"] > 0 and r["peak_mb"] > 0 and r["eigen"] > 0 for r in ours)


@pytest.mark.slow
@needs_dataset
def test_search_benchmark_reports_recall(tmp_path, capsys):
    assert search.main(["--tiny"]) == 0
    assert "recall@10" in capsys.readouterr().out
    doc = _json(tmp_path, "search-tiny")
    flat = [r for r in doc["rows"] if r["index"] == "flat"]
    assert flat and flat[0]["recall@10"] == 1.0
    assert all(0.0 <= r["recall@10"] <= 1.0 for r in doc["real_only"])


@pytest.mark.slow
@needs_dataset
def test_quality_and_throughput_benchmarks_run(tmp_path, capsys):
    assert quality.main(["--tiny"]) == 0
    doc = _json(tmp_path, "quality-tiny")
    assert [(r["pipeline"], r["encoding"]) for r in doc["rows"]] == [
        (p, e) for p in ("ours", "plain") for e in ("default", "area-weighted")
    ]
    assert all(0.0 <= r["mAP"] <= 1.0 for r in doc["rows"])
    assert throughput.main(["--tiny"]) == 0
    rows = _json(tmp_path, "throughput-tiny")["rows"]
    assert {(r["workers"], r["blas_threads"]) for r in rows} == {
        (1, 1),
        (2, 1),
        (1, "default"),
        (2, "default"),
    }
    assert "meshes_per_min" in capsys.readouterr().out


@pytest.mark.slow
@needs_dataset
def test_service_benchmark_against_a_live_server(tmp_path, capsys):
    assert service.main(["--tiny"]) == 0
    doc = _json(tmp_path, "service-tiny")
    assert doc["ingestion"]["ready"] == 16 and doc["indexed"] >= 100
    assert [q["clients"] for q in doc["queries"]] == [1, 4]
    assert all(q["p50_s"] > 0 for q in doc["queries"])
