"""A vocabulary's fusion scale belongs to the encoding it was fit for, and its words to the describe
parameters: other encode settings, and other describe parameters, are logged."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest

from app.core.pipeline import DescribeParams
from app.core.vocabulary import EncodeParams, Vocabulary
from app.services.vocabularies import _warn_if_described_otherwise, _warn_if_encoded_otherwise

FUSION = {"bof": 0.9, "dna": 45.0, "weight": 1.0, "count": 30}


def _vocab(**metadata) -> Vocabulary:
    return Vocabulary(np.zeros((2, 4), np.float32), metadata=metadata)


def test_a_scale_fit_by_area_served_by_count_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    vocab = _vocab(fusion=FUSION, encode={"mode": "hard", "keypoints_only": False, "area_weighted": True})
    with caplog.at_level(logging.WARNING, logger="app.services.vocabularies"):
        _warn_if_encoded_otherwise(vocab, EncodeParams(area_weighted=False), 7)
    [record] = caplog.records
    assert "version 7" in record.getMessage() and "'area_weighted': True" in record.getMessage()
    assert "'area_weighted': False" in record.getMessage() and "rebuild" in record.getMessage()


@pytest.mark.parametrize("metadata", [
    {"fusion": FUSION, "encode": EncodeParams().encoding()},  # agrees
    {"fusion": FUSION},  # made before vocabularies recorded their encoding
    {"encode": {"mode": "soft", "keypoints_only": True, "area_weighted": False}},  # no fusion: no scale
])
def test_nothing_to_say(metadata: dict, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="app.services.vocabularies"):
        _warn_if_encoded_otherwise(_vocab(**metadata), EncodeParams(), 1)
    assert caplog.records == []


def test_describe_changes_name_each_parameter_that_differs() -> None:
    now = DescribeParams()
    fitted = replace(now, smoothing=10, smoothing_weights="uniform").fingerprint()
    fitted = fitted.replace("fill_holes=0.05;", "")  # a vocabulary fit before fill_holes existed
    assert _vocab(describe=fitted).describe_changes(now) == {
        "fill_holes": ("?", "0.05"), "smoothing": ("10", "12"),
        "smoothing_weights": ("uniform", "capped-area")}
    assert _vocab(describe=now.fingerprint()).describe_changes(now) == {}
    assert _vocab().describe_changes(now) == {}  # a rebuilt version records no describe parameters


def test_words_fit_for_other_describe_parameters_are_logged(caplog: pytest.LogCaptureFixture) -> None:
    """A data directory from before round 14 serves the uniform-Taubin vocabulary it registered; the
    upgraded process describes with capped-area weights, and says what changed and what to do."""
    old = replace(DescribeParams(), smoothing=10, smoothing_weights="uniform").fingerprint()
    with caplog.at_level(logging.WARNING, logger="app.services.vocabularies"):
        _warn_if_described_otherwise(_vocab(describe=old), DescribeParams(), 3)
    [record] = caplog.records
    message = record.getMessage()
    assert "version 3" in message and "'smoothing_weights': 'uniform'" in message
    assert "'smoothing_weights': 'capped-area'" in message and "re-ingest" in message


@pytest.mark.parametrize("metadata", [{"describe": DescribeParams().fingerprint()}, {}])
def test_nothing_to_say_about_descriptions(metadata: dict, caplog: pytest.LogCaptureFixture) -> None:
    # the same parameters, or a rebuilt version (fit on the stored descriptions, no fingerprint kept)
    with caplog.at_level(logging.WARNING, logger="app.services.vocabularies"):
        _warn_if_described_otherwise(_vocab(**metadata), DescribeParams(), 1)
    assert caplog.records == []


def test_the_shipped_vocabulary_raises_no_describe_warning_at_the_defaults(
        caplog: pytest.LogCaptureFixture) -> None:
    from app.config import Settings

    settings = Settings()
    shipped = Vocabulary.load(settings.default_vocabulary)
    with caplog.at_level(logging.WARNING, logger="app.services.vocabularies"):
        _warn_if_described_otherwise(shipped, settings.describe.params(), 1)
    assert caplog.records == []
