"""Every describe parameter the harness measures can be set from the environment, and is checked there."""

from __future__ import annotations

import pydantic
import pytest

from app.config import Settings
from app.core.pipeline import DescribeParams
from app.core.smoothing import WEIGHTS


def test_describe_defaults_are_the_core_defaults(monkeypatch):
    for name in ("SMOOTHING", "SMOOTHING_WEIGHTS", "TIME_RANGE"):
        monkeypatch.delenv(f"SHAPEBAG_DESCRIBE__{name}", raising=False)
    params = Settings().describe.params()
    assert params == DescribeParams()


def test_smoothing_weights_and_time_range_reach_the_core(monkeypatch):
    monkeypatch.setenv("SHAPEBAG_DESCRIBE__SMOOTHING_WEIGHTS", "cotangent")
    monkeypatch.setenv("SHAPEBAG_DESCRIBE__TIME_RANGE", "weyl")
    params = Settings().describe.params()
    assert params.smoothing_weights == "cotangent" and params.time_range == "weyl"
    assert params.fingerprint() != DescribeParams().fingerprint()  # cached descriptions are not reused


@pytest.mark.parametrize("weights", WEIGHTS)  # every weighting the core has, so the settings list them all
def test_every_smoothing_weighting_is_accepted_from_the_environment(monkeypatch, weights):
    monkeypatch.setenv("SHAPEBAG_DESCRIBE__SMOOTHING_WEIGHTS", weights)
    assert Settings().describe.params().smoothing_weights == weights


@pytest.mark.parametrize("name", ["SMOOTHING_WEIGHTS", "TIME_RANGE"])
def test_unknown_values_are_refused_at_start(monkeypatch, name):
    monkeypatch.setenv(f"SHAPEBAG_DESCRIBE__{name}", "bogus")
    with pytest.raises(pydantic.ValidationError):
        Settings()


def test_the_antialias_ramp_reaches_the_core_and_a_reversed_one_is_refused(monkeypatch):
    monkeypatch.setenv("SHAPEBAG_DESCRIBE__ANTIALIAS_START", "2")
    monkeypatch.setenv("SHAPEBAG_DESCRIBE__ANTIALIAS_FULL", "6.5")
    params = Settings().describe.params()
    assert (params.antialias_start, params.antialias_full) == (2.0, 6.5)
    assert params.fingerprint() != DescribeParams().fingerprint()
    monkeypatch.setenv("SHAPEBAG_DESCRIBE__ANTIALIAS_START", "8")
    with pytest.raises(pydantic.ValidationError, match="antialias_start"):
        Settings()


def test_encode_defaults_are_the_core_defaults_and_bad_values_are_refused(monkeypatch):
    from app.core.vocabulary import EncodeParams

    for name in ("MODE", "SIGMA_SCALE", "KEYPOINTS_ONLY", "AREA_WEIGHTED", "FUSION"):
        monkeypatch.delenv(f"SHAPEBAG_ENCODE__{name}", raising=False)
    assert Settings().encode.params() == EncodeParams()
    bad = (("MODE", "fuzzy"), ("SIGMA_SCALE", "0"), ("SIGMA_SCALE", "-1"), ("SIGMA_SCALE", "nan"))
    for name, value in bad:
        monkeypatch.setenv(f"SHAPEBAG_ENCODE__{name}", value)
        with pytest.raises(pydantic.ValidationError, match=name.lower()):
            Settings()
        monkeypatch.delenv(f"SHAPEBAG_ENCODE__{name}")
    monkeypatch.setenv("SHAPEBAG_ENCODE__MODE", "hard")
    monkeypatch.setenv("SHAPEBAG_ENCODE__SIGMA_SCALE", "0.7")
    assert (Settings().encode.params().mode, Settings().encode.params().sigma_scale) == ("hard", 0.7)


def test_remeshing_without_its_extra_is_refused_at_start_saying_how_to_get_it(monkeypatch):
    import app.config

    monkeypatch.setenv("SHAPEBAG_DESCRIBE__REMESH", "true")
    assert Settings().describe.params().remesh  # gpytoolbox is installed here (the dev extra holds it)
    monkeypatch.setattr(app.config, "find_spec", lambda name: None if name == "gpytoolbox" else object())
    with pytest.raises(pydantic.ValidationError, match=r"shapebag\[remesh\]"):
        Settings()
    monkeypatch.setenv("SHAPEBAG_DESCRIBE__REMESH", "false")
    assert not Settings().describe.params().remesh  # the default needs nothing more


def test_the_default_data_dir_is_data_and_the_datasets_come_from_one_setting(monkeypatch, tmp_path):
    from app.datasets import locate

    monkeypatch.delenv("SHAPEBAG_DATA_DIR", raising=False)
    assert str(Settings().data_dir) == "data"
    monkeypatch.setenv("SHAPEBAG_DATASETS", str(tmp_path))
    assert locate.dataset_dir("realworld") == tmp_path / "realworld"
    reason = locate.missing_reason("shrec11-simplified")
    assert reason and str(tmp_path / "shrec11-simplified") in reason and "SHAPEBAG_DATASETS" in reason
    with pytest.raises(locate.DatasetMissing, match="shrec11-simplified"):
        locate.require("shrec11-simplified")
    (tmp_path / "shrec11-simplified").mkdir()
    assert locate.missing_reason("shrec11-simplified") is not None  # a folder without labels.csv is not it
    (tmp_path / "shrec11-simplified" / "labels.csv").write_text("file,class\n")
    assert locate.require("shrec11-simplified") == tmp_path / "shrec11-simplified"
    assert locate.main(["shrec11-simplified", "realworld"]) == 2  # realworld is still missing
    monkeypatch.delenv("SHAPEBAG_DATASETS")
    assert locate.datasets_root() == locate.REPO_ROOT.parent / "shared" / "datasets"
