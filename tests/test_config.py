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
