"""A vocabulary's fusion scale belongs to the encoding it was fit for: other encode settings are logged."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from app.core.vocabulary import EncodeParams, Vocabulary
from app.services.vocabularies import _warn_if_encoded_otherwise

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
