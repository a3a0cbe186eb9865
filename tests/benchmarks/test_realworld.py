"""The realworld, self-retrieval and large-input benchmarks run end to end on 2-3 files (no timing
assertions)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import common, large_inputs, realworld, selfretrieval
from tests.conftest import needs_dataset

needs_corpus = needs_dataset("realworld")


@pytest.fixture(autouse=True)
def _results_in_tmp(tmp_path, monkeypatch):
    monkeypatch.setattr(common, "RESULTS_DIR", tmp_path / "results")


def _json(tmp_path, name: str) -> dict:
    return json.loads((tmp_path / "results" / f"{name}.json").read_text())


def test_percentiles_interpolate_like_numpy():
    assert realworld.percentile([4.0, 1.0, 3.0, 2.0], 50) == 2.5
    assert realworld.percentile([1.0, 2.0, 3.0, 4.0, 5.0], 90) == pytest.approx(4.6)
    assert realworld.distribution([2.0])["max"] == 2.0


def test_summary_counts_outcomes_and_files_outside_the_band():
    rows = [
        {"file": "a", "outcome": "described", "describe_s": 0.5, "describe_cpu_s": 0.4,
         "vertices_solved": 1600, "target": 1000},
        {"file": "b", "outcome": "described", "describe_s": 0.1, "describe_cpu_s": 0.1,
         "vertices_solved": 900, "target": 1000},
        {"file": "c", "outcome": "refused", "message": "the file is empty"},
        {"file": "d", "outcome": "timeout"},
    ]
    s = realworld.summarise(rows)
    assert s["counts"] == {"described": 2, "refused": 1, "error": 0, "crash": 0, "timeout": 1}
    assert s["solved_above_band"] == ["a"] and s["solved_below_band"] == []
    assert s["slowest"] == "a" and s["describe_s"]["max"] == 0.5


@pytest.mark.slow
@needs_corpus
def test_realworld_benchmark_describes_refuses_and_zips_folders(tmp_path, capsys):
    code = realworld.main(["--files", "oded__wingnut.obj", "--files", "trimesh__empty.stl",
                           "--files", "gltf_fox", "--name", "rw-smoke"])
    out = capsys.readouterr().out
    assert "describe seconds" in out and "oded__wingnut.obj" in out
    doc = _json(tmp_path, "rw-smoke")
    rows = {r["file"]: r for r in doc["rows"]}
    assert set(rows) == {"oded__wingnut.obj", "trimesh__empty.stl", "gltf_fox"}
    wingnut = rows["oded__wingnut.obj"]
    assert wingnut["outcome"] == "described"
    assert wingnut["target"] / 1.5 <= wingnut["vertices_solved"] <= 1.5 * wingnut["target"]
    assert 0.95 < wingnut["area_ratio"] < 1.05 and 0 < wingnut["mean_dist_pct"] < wingnut["hausdorff_pct"]
    assert rows["trimesh__empty.stl"]["outcome"] == "refused" and rows["trimesh__empty.stl"]["message"]
    assert rows["gltf_fox"]["outcome"] in ("described", "refused")  # whatever the loader says of a .zip
    assert sum(doc["summary"]["counts"].values()) == 3
    assert code == 0


@pytest.mark.slow
@needs_corpus
def test_realworld_benchmark_prices_another_resolution(tmp_path):
    """--target-vertices reaches the child: the file is solved at that resolution, and it is recorded."""
    code = realworld.main(["--files", "oded__wingnut.obj", "--target-vertices", "500", "--k", "120",
                           "--name", "rw-500"])
    doc = _json(tmp_path, "rw-500")
    assert doc["overrides"] == {"target_vertices": 500, "k": 120}
    (row,) = doc["rows"]
    assert row["outcome"] == "described" and row["target"] == 500
    assert 500 / 1.5 <= row["vertices_solved"] <= 500 * 1.5
    assert code == 0


@pytest.mark.slow
@needs_corpus
def test_realworld_benchmark_prices_another_smoothing(tmp_path):
    """--smoothing and --smoothing-weights reach the child's DescribeParams: a known setting describes the
    file and is recorded; an unknown one is refused before any file is run."""
    wingnut = ["--files", "oded__wingnut.obj"]
    code = realworld.main([*wingnut, "--smoothing", "12", "--smoothing-weights", "area", "--name", "rw-area"])
    doc = _json(tmp_path, "rw-area")
    assert doc["overrides"] == {"smoothing": 12, "smoothing_weights": "area"}
    assert [r["outcome"] for r in doc["rows"]] == ["described"] and code == 0
    assert realworld.main([*wingnut, "--smoothing-weights", "laplace", "--name", "rw-bad"]) == 2
    assert not (tmp_path / "results" / "rw-bad.json").exists()


@pytest.mark.slow
@needs_corpus
def test_large_inputs_benchmark_runs_ours_and_the_baseline(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(large_inputs, "SIZES", {"tiny": ("oded__wingnut.obj", 1)})  # 3k -> 12k vertices
    assert large_inputs.main(["--sizes", "tiny", "--baseline", "--name", "large-smoke"]) == 0
    assert "peak_mb" in capsys.readouterr().out
    rows = _json(tmp_path, "large-smoke")["rows"]
    assert [r["simplify"] for r in rows] == ["legacy", "ours"]
    for r in rows:
        assert r["outcome"] == "described" and r["vertices_in"] > 10_000
        assert r["peak_mb"] >= r["load_peak_mb"] >= r["base_mb"] > 0


def test_self_retrieval_scores_ranks_by_l1_with_ties_for_the_copy():
    originals = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]])
    # copy 0 nearest its own; copy 1 as near to original 0 as to its own (L1 0.5 both: a tie, rank 1);
    # copy 2 nearer originals 1 (L1 1.2) and 0 (2.2) than its own (2.8): rank 3
    queries = np.array([[0.2, 0.0], [0.5, 0.0], [1.2, 1.0]])
    s = selfretrieval.scores(queries, originals)
    assert s["NN"] == pytest.approx(2 / 3)
    assert s["MRR"] == pytest.approx((1 + 1 + 1 / 3) / 3)
    assert s["top5"] == 1.0


def test_self_retrieval_under_the_rerank_ranks_exact_copies_first_and_a_moved_copy_not():
    rng = np.random.default_rng(0)
    originals = rng.random((12, 6))  # fused layout: 4 BoF words, then 2 Shape-DNA entries (weight 1)
    assert selfretrieval.scores(originals.copy(), originals, (4, 1.0))["NN"] == 1.0
    far = originals.copy()
    far[0] += 100.0  # copy 0 left every original: nearer to the originals with larger entries than its own
    s = selfretrieval.scores(far, originals, (4, 1.0))
    assert s["NN"] == pytest.approx(11 / 12) and s["MRR"] < 1.0


@pytest.mark.slow
@needs_corpus
def test_self_retrieval_benchmark_finds_copies_and_records_the_setting(tmp_path, capsys):
    code = selfretrieval.main(["--files", "oded__wingnut.obj", "--files", "oded__demosthenes-low-res.obj",
                               "--files", "trimesh__empty.stl", "--fill-holes", "0", "--name", "sr-smoke"])
    out = capsys.readouterr().out
    assert "fused (served) | retriangulated" in out and code == 0
    doc = _json(tmp_path, "sr-smoke")
    assert doc["files"] == 2 and doc["refused"] == 1 and doc["describe"] == {"fill_holes": 0.0}
    for line in doc["lines"].values():
        assert 0.5 <= line["MRR"] <= 1.0 and line["top5"] == 1.0  # of two, its own is at worst second
