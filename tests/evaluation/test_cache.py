"""The evaluation's description cache: one entry per mesh, parameters, variant and core code."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.core.keypoints import KeypointFilter
from app.core.pipeline import DescribeParams
from app.evaluation import cache as evaluation_cache


def test_cache_keys_separate_parameters_variants_and_code(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cache = evaluation_cache.DescriptionCache(tmp_path)
    clean, noisy = evaluation_cache.Variant(), evaluation_cache.Variant(0.01, 0)
    p1, p2 = DescribeParams(), DescribeParams(keypoint_filter=KeypointFilter(enabled=True))
    paths = {cache.description_path("ab", p, v) for p in (p1, p2) for v in (clean, noisy)}
    assert len(paths) == 4
    # an edit to the core code that computes descriptions must not reuse old entries
    fingerprint = evaluation_cache.code_fingerprint(exclude=("pipeline",))
    monkeypatch.setitem(evaluation_cache._FINGERPRINTS, "describe", fingerprint)
    assert evaluation_cache.DescriptionCache(tmp_path).description_path("ab", p1, clean) not in paths
