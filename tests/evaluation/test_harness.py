"""The evaluation harness on a small SHREC'11 subset (3 classes x 4 meshes, copied into tmp_path)."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from app.cli import CommandError
from app.core.metrics import METRICS
from app.core.pipeline import ShapeDescription
from app.core.vocabulary import Vocabulary
from app.evaluation import cache as evaluation_cache
from app.evaluation.harness import evaluate
from app.evaluation.report import format_table, to_json
from app.evaluation.results import EvaluationError, EvaluationOptions
from tests.conftest import dataset_or_skip

CLASSES = ("alien", "ants", "armadillo")


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    shrec = dataset_or_skip("shrec11-simplified")
    root = tmp_path_factory.mktemp("subset")
    lines = ["file,class"]
    for cls in CLASSES:
        (root / cls).mkdir()
        for src in sorted((shrec / cls / "train").glob("*.obj"))[:4]:
            shutil.copy(src, root / cls / src.name)
            lines.append(f"{cls}/{src.name},{cls}")
    (root / "labels.csv").write_text("\n".join(lines) + "\n")
    return root


def _options(cache: Path, **kw: object) -> EvaluationOptions:
    # raw resolution (~250 vertices): a fast dense eigen-solve keeps the test short
    base = dict(
        rows=("run5", "run1", "shape-dna", "d2"),
        vocabulary_size=8,
        target_vertices=0,
        workers=2,
        cache_dir=cache,
        progress=False,
    )
    base.update(kw)
    return EvaluationOptions(**base)  # type: ignore[arg-type]


def _forbid_recompute(monkeypatch: pytest.MonkeyPatch) -> None:
    def boom(*args: object, **kwargs: object) -> None:
        raise AssertionError("the cache should have answered")

    monkeypatch.setattr(evaluation_cache, "describe", boom)
    monkeypatch.setattr(evaluation_cache, "d2_histogram", boom)


def test_table_rows_and_second_run_reads_the_cache(
    folder: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    first = evaluate(folder, _options(tmp_path))
    assert [r.name for r in first.rows] == ["run5", "run1", "shape-dna", "d2"]
    assert (first.shapes, first.classes) == (12, 3)
    assert first.describe["computed"] == 12 and first.describe["cached"] == 0
    assert first.describe["d2_computed"] == 12
    for row in first.rows:
        assert set(row.scores) == set(METRICS)
        assert all(0.0 <= v <= 1.0 for v in row.scores.values())
        # 12 shapes, C = 4: at most 3 hits in the first min(32, 11) = 11 -> E <= 2*3/(3+11) = 3/7
        assert row.scores["E"] <= 3 / 7 + 1e-12
    assert [r.d for r in first.rows] == [4, 6, 30, 64]

    # other BoF settings, in this process, with describe() and D2 forbidden: all from the cache
    _forbid_recompute(monkeypatch)
    second = evaluate(folder, _options(tmp_path, workers=1, mode="soft", keypoints_only=True))
    assert second.describe["computed"] == 0 and second.describe["cached"] == 12
    assert second.describe["d2_computed"] == 0
    # baselines do not depend on the BoF settings: identical figures from the cached inputs
    assert second.rows[2].scores == first.rows[2].scores
    assert second.rows[3].scores == first.rows[3].scores
    # same settings again: deterministic
    third = evaluate(folder, _options(tmp_path, workers=1))
    assert [r.scores for r in third.rows] == [r.scores for r in first.rows]

    table = format_table(first)
    assert table.splitlines()[0].split()[:8] == ["Row", "NN", "FT", "ST", "E", "DCG", "mAP(%)", "d"]
    assert "12 computed" in table


def test_variant_lines_noise_frozen_and_half_fit(folder: Path, tmp_path: Path) -> None:
    frozen_dir = Vocabulary.fit_features(np.random.default_rng(0).random((200, 4)), size=8, run="run5").save(
        tmp_path / "frozen-v1"
    )
    result = evaluate(
        folder,
        _options(
            tmp_path / "cache", rows=("run5", "shape-dna"), noise=0.01, vocabulary=frozen_dir, fit_on="half"
        ),
    )
    names = [r.name for r in result.rows]
    assert names == [
        "run5",
        "run5 [frozen frozen-v1]",
        "run5 [frozen frozen-v1] [noise 0.01]",
        "run5 [fit on 2/3 classes]",
        "run5 [noise 0.01]",
        "shape-dna",
        "shape-dna [noise 0.01]",
    ]
    main, served = result.rows[0], result.rows[1]
    for line in (served, *result.rows[3:5]):
        assert line.reference is main
        assert line.delta_map == pytest.approx(line.scores["mAP"] - main.scores["mAP"])
    # the served noise line: the frozen words on the noisy queries, its drop from the served clean line
    served_noise = result.rows[2]
    assert served_noise.reference is served
    assert served_noise.delta_map == pytest.approx(served_noise.scores["mAP"] - served.scores["mAP"])
    # clean and noisy descriptions are separate cache entries: 12 + 12 eigen-solves
    assert result.describe["computed"] == 24
    noisy_files = list((tmp_path / "cache").rglob("*.noise0.01-s0.npz"))
    assert len(noisy_files) == 12
    doc = to_json(result)
    assert json.loads(json.dumps(doc))["rows"][4]["reference"] == "run5"


def test_a_fused_row_is_scored_with_the_frozen_words_and_their_scales(folder: Path, tmp_path: Path) -> None:
    """The fused frozen line is what the service serves: the vocabulary's words and its stored scales."""
    cache = tmp_path / "cache"
    evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4))  # describes into the cache
    shapes = [ShapeDescription.load(p) for p in sorted(cache.rglob("*.npz")) if "noise" not in p.name]
    words = Vocabulary.fit(shapes, size=4, run="run5", seed=3)  # words of these shapes: few BoF ties

    def with_scales(name: str, bof: float, dna: float) -> Path:
        meta = {**words.metadata, "fusion": {"bof": bof, "dna": dna, "weight": 1.0, "count": 10}}
        return Vocabulary(words.centers, run="run5", sigma=words.sigma, metadata=meta).save(tmp_path / name)

    # a DNA scale so large that the DNA part only breaks the BoF's ties
    result = evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4, fusion=(0.5, 1.0),
                                       vocabulary=with_scales("faint", 1.0, 1e12)))
    names = [r.name for r in result.rows]
    # no frozen line at w = 0.5: the vocabulary's scales were fixed for w = 1
    assert names == ["run5", "run5 [frozen faint]", "run5 + 0.5 DNA", "run5 + 1 DNA",
                     "run5 + 1 DNA [frozen faint]"]
    faint = result.rows[4]
    assert faint.reference is result.rows[3]
    # the stored scales are used, not refit on the data: the same words with a BoF scale so large that
    # only the DNA ranks give another figure (refit scales would give the same one twice)
    dna_only = evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4, fusion=(1.0,),
                                         vocabulary=with_scales("dna", 1e12, 1.0)))
    assert dna_only.rows[-1].name == "run5 + 1 DNA [frozen dna]"
    assert dna_only.rows[-1].scores["mAP"] != pytest.approx(faint.scores["mAP"], abs=1e-6)
    assert dna_only.rows[2].scores == result.rows[3].scores  # the self-fit fused line does not change
    # the same words without scales: no fused frozen line
    bare = evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4, fusion=(1.0,),
                                     vocabulary=words.save(tmp_path / "bare")))
    assert [r.name for r in bare.rows] == ["run5", "run5 [frozen bare]", "run5 + 1 DNA"]
    # scales fit on hard BoFs are not used to score soft ones (nor the other way round): refused, saying how
    meta = {**words.metadata, "fusion": {"bof": 1.0, "dna": 1.0, "weight": 1.0, "count": 10},
            "encode": {"mode": "hard", "keypoints_only": False, "area_weighted": True}}
    hard_fit = Vocabulary(words.centers, run="run5", sigma=words.sigma, metadata=meta).save(tmp_path / "hard")
    with pytest.raises(EvaluationError, match=r"fit with \{'mode': 'hard'\}.*--mode hard"):
        evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4, fusion=(1.0,),
                                  vocabulary=hard_fit))
    served = evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4, fusion=(1.0,),
                                       vocabulary=hard_fit, mode="hard"))
    assert served.rows[-1].name == "run5 + 1 DNA [frozen hard]"
    pure = evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4, vocabulary=hard_fit))
    assert [r.name for r in pure.rows] == ["run5", "run5 [frozen hard]"]  # no scale used: no objection


def test_frozen_vocabulary_of_another_run_is_refused(folder: Path, tmp_path: Path) -> None:
    vocab_dir = Vocabulary.fit_features(np.random.default_rng(0).random((100, 6)), size=4, run="run1").save(
        tmp_path / "v"
    )
    with pytest.raises(EvaluationError, match="encodes run1"):
        evaluate(folder, _options(tmp_path, rows=("run5",), vocabulary=vocab_dir))


def test_bad_folders_give_clear_errors(folder: Path, tmp_path: Path) -> None:
    with pytest.raises(EvaluationError, match="labels.csv"):
        evaluate(tmp_path, _options(tmp_path / "c"))
    broken = tmp_path / "broken"
    shutil.copytree(folder, broken)
    (broken / "ants" / "bad.obj").write_text("v 0 0 0\nv 1 0 0\n")  # two points, no faces
    with (broken / "labels.csv").open("a") as fh:
        fh.write("ants/bad.obj,ants\n")
    with pytest.raises(EvaluationError, match=r"1 mesh\(es\) could not be described: .*bad.obj"):
        evaluate(broken, _options(tmp_path / "c", rows=("run5",)))
    with pytest.raises(EvaluationError, match="unknown row"):
        evaluate(folder, _options(tmp_path / "c", rows=("run9",)))
    for sigma in (0.0, -1.0, float("nan")):
        with pytest.raises(EvaluationError, match="--sigma-scale must be > 0"):
            evaluate(folder, _options(tmp_path / "c", rows=("run5",), sigma_scale=sigma))


@pytest.mark.slow  # the evaluation command end to end on the SHREC'11 subset
def test_command_prints_the_table_and_writes_json(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from app.commands import evaluate as command

    parser = argparse.ArgumentParser()
    command.register(parser.add_subparsers())
    out = tmp_path / "table.json"
    args = parser.parse_args(
        [
            "evaluate",
            str(folder),
            "--runs",
            "run5,d2",
            "--target-vertices",
            "0",
            "--vocabulary-size",
            "8",
            "--cache-dir",
            str(tmp_path / "c"),
            "--json",
            str(out),
            "--quiet",
            "--workers",
            "1",
        ]
    )
    assert args.func(args) == 0
    printed = capsys.readouterr().out
    assert printed.splitlines()[2].startswith("run5 ")
    doc = json.loads(out.read_text())
    assert [r["name"] for r in doc["rows"]] == ["run5", "d2"]
    assert doc["options"]["target_vertices"] == 0
    bad = parser.parse_args(["evaluate", str(folder), "--runs", " , "])
    with pytest.raises(CommandError, match="names no row"):
        bad.func(bad)


def test_seeds_average_the_bof_lines_over_k_means_seeds(folder: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    rows = ("run5",)
    single = [evaluate(folder, _options(cache, rows=rows, fit_on="half", seed=s)) for s in (3, 4)]
    # the noisy queries keep the first seed's noise: only the vocabulary's k-means seed varies
    both = evaluate(folder, _options(cache, rows=rows, noise=0.01, fit_on="half", seed=3, seeds=2))
    assert [r.name for r in both.rows] == ["run5", "run5 [fit on 2/3 classes]", "run5 [noise 0.01]"]
    for i, line in enumerate(both.rows[:2]):
        per_seed = [s.rows[i].scores for s in single]
        for metric, value in line.scores.items():
            assert value == pytest.approx(np.mean([p[metric] for p in per_seed]))
        assert line.details["mAP_per_seed"] == pytest.approx([p["mAP"] for p in per_seed])
        assert line.details["mAP_sd"] == pytest.approx(np.std([p["mAP"] for p in per_seed]))
    assert len(both.rows[2].details["mAP_per_seed"]) == 2
    main = both.rows[0]
    assert all(line.reference is main for line in both.rows[1:])  # Δ against the mean clean line
    assert "mean over 2 k-means seeds" in format_table(both)
    with pytest.raises(EvaluationError, match="--seeds"):
        evaluate(folder, _options(cache, rows=rows, seeds=0))
    with pytest.raises(EvaluationError, match="subdivision"):
        evaluate(folder, _options(cache, rows=rows, subdivision="butterfly"))


def test_per_class_breakdown_is_in_the_json_and_printed_on_request(folder: Path, tmp_path: Path) -> None:
    result = evaluate(folder, _options(tmp_path / "cache", rows=("run5",), noise=0.01, per_class=True))
    main = result.rows[0]
    breakdown = main.details["per_class"]
    labels = {line.split(",")[1] for line in (folder / "labels.csv").read_text().splitlines()[1:]}
    assert set(breakdown) == labels
    # the per-class means, weighted by class size (equal here), give the line's mAP back
    assert np.mean([v["mAP"] for v in breakdown.values()]) == pytest.approx(main.scores["mAP"])
    assert all(other != cls for cls, v in breakdown.items() for other in v["intruders"])
    table = format_table(result)
    assert "run5: " in table and "classes below 99.5 % mAP" in table
    assert "run5 [noise 0.01]: " in table  # the variant lines say where they lose too
    doc = json.loads(json.dumps(to_json(result)))
    assert set(doc["rows"][0]["details"]["per_class"]) == labels


def test_queries_from_another_folder(folder: Path, tmp_path: Path) -> None:
    from benchmarks.variants import generate

    cache = tmp_path / "cache"
    rows = ("run5", "shape-dna")
    # the same files under the same names: each query is its database counterpart, left out of its
    # ranking, so the line must equal the clean line exactly
    same = tmp_path / "same"
    shutil.copytree(folder, same)
    result = evaluate(folder, _options(cache, rows=rows, queries=same))
    names = [r.name for r in result.rows]
    assert names == ["run5", "run5 [queries same]", "shape-dna", "shape-dna [queries same]"]
    for main, cross in ((result.rows[0], result.rows[1]), (result.rows[2], result.rows[3])):
        assert cross.reference is main and cross.scores == pytest.approx(main.scores)
    # with a frozen vocabulary, the served line of the same queries equals the served clean line
    random_words = Vocabulary.fit_features(np.random.default_rng(0).random((200, 4)), size=8, run="run5")
    words = random_words.save(tmp_path / "words")
    served = evaluate(folder, _options(cache, rows=("run5",), queries=same, vocabulary=words,
                                       vocabulary_size=4))
    assert [r.name for r in served.rows] == [
        "run5", "run5 [frozen words]", "run5 [frozen words] [queries same]", "run5 [queries same]"]
    clean_served, cross_served = served.rows[1], served.rows[2]
    assert cross_served.reference is clean_served
    assert cross_served.scores == pytest.approx(clean_served.scores)
    assert clean_served.scores["mAP"] != pytest.approx(served.rows[0].scores["mAP"])  # not the self-fit words
    # other names: nothing pairs, every query ranks the whole database and finds its twin first
    renamed = tmp_path / "renamed"
    renamed.mkdir()
    lines = ["file,class"]
    for i, line in enumerate((folder / "labels.csv").read_text().splitlines()[1:]):
        name, cls = line.split(",")
        shutil.copy(folder / name, renamed / f"q{i}.obj")
        lines.append(f"q{i}.obj,{cls}")
    (renamed / "labels.csv").write_text("\n".join(lines) + "\n")
    unpaired = evaluate(folder, _options(cache, rows=rows, queries=renamed))
    assert unpaired.rows[1].scores["NN"] == 1.0
    # another triangulation of every shape (benchmarks/variants.py): described and scored as queries
    remesh = generate(folder, tmp_path / "remesh", vertex_range=(300, 400))
    cross = evaluate(folder, _options(cache, rows=("run5",), queries=remesh)).rows[1]
    assert cross.name == "run5 [queries remesh]" and 0.0 <= cross.scores["mAP"] <= 1.0


def test_fusion_rows(folder: Path, tmp_path: Path) -> None:
    result = evaluate(folder, _options(tmp_path / "cache", rows=("run5",), fusion=(0.0, 1.0), noise=0.01))
    names = [r.name for r in result.rows]
    assert names == ["run5", "run5 [noise 0.01]", "run5 + 0 DNA", "run5 + 0 DNA [noise 0.01]",
                     "run5 + 1 DNA", "run5 + 1 DNA [noise 0.01]"]
    plain, zero, fused = result.rows[0], result.rows[2], result.rows[4]
    # weight 0: the fused distance is the BoF distance over a constant, the same ranking up to the
    # rounding of the L1 sum of scaled terms, which can flip an exact tie between two BoF distances
    # (one swapped pair in this small folder moves a score by under 0.01)
    assert zero.scores == pytest.approx(plain.scores, abs=0.01)
    # d is the descriptor's (Run 5: 4); the vectors ranked are the words plus the Shape-DNA
    assert zero.d == fused.d == plain.d == 4
    assert fused.details["vector_length"] == plain.details["vector_length"] + 30 == 8 + 30
    assert fused.details["fusion"] == 1.0 and plain.details["fusion"] is None
    with pytest.raises(EvaluationError, match="fusion"):
        evaluate(folder, _options(tmp_path / "cache", rows=("run5",), fusion=(-1.0,)))


def _stopped_command(
    monkeypatch: pytest.MonkeyPatch,
) -> tuple[argparse.ArgumentParser, list[EvaluationOptions]]:
    """The `evaluate` command's parser, its evaluation replaced by one that records the options it gets
    and stops (CommandError "stop here"), and the list it records into."""
    from app.commands import evaluate as command

    seen: list[EvaluationOptions] = []

    def fake(directory: Path, options: EvaluationOptions) -> None:
        seen.append(options)
        raise EvaluationError("stop here")

    monkeypatch.setattr(command, "evaluate", fake)
    parser = argparse.ArgumentParser()
    command.register(parser.add_subparsers())
    return parser, seen


def test_command_passes_the_new_flags(folder: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from app.core.keypoints import KeypointFilter

    parser, seen = _stopped_command(monkeypatch)
    args = parser.parse_args(["evaluate", str(folder), "--queries", str(tmp_path), "--fusion", "0.5, 1",
                              "--filter", "--time-range", "weyl", "--smoothing-weights", "cotangent",
                              "--area-weighted", "--mode", "hard", "--sigma-scale", "0.7"])
    with pytest.raises(CommandError, match="stop here"):
        args.func(args)
    opts = seen[0]
    assert (opts.mode, opts.sigma_scale) == ("hard", 0.7)
    assert opts.queries == tmp_path and opts.fusion == (0.5, 1.0) and opts.keypoint_filter
    assert (opts.time_range, opts.smoothing_weights, opts.area_weighted) == ("weyl", "cotangent", True)
    # without --filter/--no-filter the default is DescribeParams'
    plain = parser.parse_args(["evaluate", str(folder)])
    with pytest.raises(CommandError):
        plain.func(plain)
    assert seen[1].keypoint_filter == KeypointFilter().enabled is False
    assert seen[1].area_weighted is True  # eq. 7 by default
    assert (seen[1].mode, seen[1].sigma_scale) == ("soft", 1.0)  # soft VQ by default (issue 11, round 7)
    per_vertex = parser.parse_args(["evaluate", str(folder), "--no-area-weighted"])
    with pytest.raises(CommandError):
        per_vertex.func(per_vertex)
    assert seen[2].area_weighted is False
    bad = parser.parse_args(["evaluate", str(folder), "--fusion", "heavy"])
    with pytest.raises(CommandError, match="--fusion"):
        bad.func(bad)
    ramped = parser.parse_args(["evaluate", str(folder), "--antialias", "0.7", "--antialias-ramp", "2,6"])
    with pytest.raises(CommandError):
        ramped.func(ramped)
    assert (seen[3].antialias, seen[3].antialias_ramp) == (0.7, (2.0, 6.0))
    assert seen[2].antialias_ramp == (4.0, 12.0)  # DescribeParams' ramp by default
    for wrong in ("6,2", "4", "a,b"):
        with pytest.raises(SystemExit):
            parser.parse_args(["evaluate", str(folder), "--antialias-ramp", wrong])


def test_paper_preset_is_the_papers_method(folder: Path, tmp_path: Path) -> None:
    # the paper's k = 300 at the raw resolution, no smoothing, the computed t_min and the cotangent
    # Laplacian, whatever the defaults
    result = evaluate(folder, _options(tmp_path / "cache", rows=("paper",)))
    describe = result.rows[0].details["describe"]
    wanted = ("k=300", "laplacian=cotangent", "remesh=False", "smoothing=0", "target_vertices=0",
              "time_range=spectrum")
    for part in wanted:
        assert part in describe.split(";"), (part, describe)
    # and eq. 8, the sum over vertices, and hard VQ, though the default BoF is eq. 7's soft integral
    assert result.rows[0].details["encode"]["area_weighted"] is False
    assert result.rows[0].details["encode"]["mode"] == "hard"


def test_the_paper_row_runs_only_when_asked(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """It solves at each mesh's own resolution (tens of seconds on a fine scan): not a default."""
    from app.evaluation.results import DEFAULT_ROWS, ROW_NAMES

    parser, seen = _stopped_command(monkeypatch)
    for argv in ([], ["--runs", "all"], ["--runs", "run5,paper"]):
        args = parser.parse_args(["evaluate", str(tmp_path), *argv])
        with pytest.raises(CommandError, match="stop here"):
            args.func(args)
    assert "paper" not in seen[0].rows and "paper" not in EvaluationOptions().rows
    assert seen[0].rows == DEFAULT_ROWS and set(DEFAULT_ROWS) | {"paper"} == set(ROW_NAMES)
    assert seen[1].rows == ROW_NAMES and seen[2].rows == ("run5", "paper")


def test_the_progress_line_names_the_rows_it_describes_for(
    folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    evaluate(folder, _options(tmp_path / "cache", rows=("run5", "run1", "paper", "shape-dna"), workers=1,
                              progress=True, fusion=(1.0,)))
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("describe")]
    heads = {line.split(":")[0] for line in lines}
    # one describe pass per parameter set, named by every row it serves (fused rows share their row's)
    assert heads == {"describe for run5, run1, shape-dna", "describe for paper"}, lines


def test_adaptive_fusion_adds_a_served_rerank_line_per_frozen_line(folder: Path, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4))  # describes into the cache
    shapes = [ShapeDescription.load(p) for p in sorted(cache.rglob("*.npz")) if "noise" not in p.name]
    words = Vocabulary.fit(shapes, size=4, run="run5", seed=3).with_fusion(shapes, weight=1.0)
    frozen = words.save(tmp_path / "fused")
    result = evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4, fusion=(1.0,), noise=0.01,
                                       vocabulary=frozen, adaptive_fusion=True))
    by_name = {r.name: r for r in result.rows}
    fixed = by_name["run5 + 1 DNA [frozen fused]"]
    clean = by_name["run5 + 1 DNA [frozen fused] [adaptive]"]
    noisy = by_name["run5 + 1 DNA [frozen fused] [noise 0.01] [adaptive]"]
    assert clean.reference is fixed and noisy.reference is by_name["run5 + 1 DNA [frozen fused] [noise 0.01]"]
    assert 0 < clean.scores["mAP"] <= 1 and 0 < noisy.scores["mAP"] <= 1
    plain = evaluate(folder, _options(cache, rows=("run5",), vocabulary_size=4, fusion=(1.0,),
                                      vocabulary=frozen))
    assert not any("[adaptive]" in r.name for r in plain.rows)  # only when asked


def test_command_passes_adaptive_fusion(folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    parser, seen = _stopped_command(monkeypatch)
    for argv, want in ((["--adaptive-fusion"], True), ([], False)):
        args = parser.parse_args(["evaluate", str(folder), *argv])
        with pytest.raises(CommandError, match="stop here"):
            args.func(args)
        assert seen[-1].adaptive_fusion is want
