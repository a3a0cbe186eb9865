"""benchmarks.describe_cost: the override it prices is typed like the DescribeParams field."""

from __future__ import annotations

import pytest

from benchmarks.describe_cost import parse_override


def test_an_override_takes_the_type_of_its_field():
    assert parse_override("antialias=0") == {"antialias": 0.0}
    assert parse_override("smoothing=20") == {"smoothing": 20}
    assert parse_override("remesh=true") == {"remesh": True}
    assert parse_override("laplacian=cotangent") == {"laplacian": "cotangent"}


@pytest.mark.parametrize("text", ["antialias", "no_such_field=1", "k="])
def test_anything_else_is_refused_with_its_text(text):
    with pytest.raises(SystemExit, match="NAME=VALUE"):
        parse_override(text)
