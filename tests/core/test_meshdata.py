"""The reader's size budget at its edges."""

from __future__ import annotations

import pytest

from app.core.meshdata import FACE_FACTOR, RAW_VERTEX_FACTOR, Budget, InvalidMeshError


def test_zero_faces_declared_pass_the_budget_and_a_negative_count_is_corrupt():
    Budget(10).faces(0, "the header")
    Budget().faces(0, "the header")
    with pytest.raises(InvalidMeshError) as info:
        Budget(10).faces(-1, "the header")
    assert str(info.value) == "the file is corrupt: the header declares a negative count"


def test_faces_up_to_exactly_the_factor_times_the_limit_pass():
    Budget(10).faces(FACE_FACTOR * 10, "the header")
    with pytest.raises(InvalidMeshError, match="declares 81 faces"):
        Budget(10).faces(FACE_FACTOR * 10 + 1, "the header")


def test_containers_may_unpack_at_least_64_mib_and_256_bytes_per_vertex():
    assert Budget(1000).unpacked_bytes() == 64 << 20
    assert Budget(1_000_000).unpacked_bytes() == 256_000_000
    assert Budget().unpacked_bytes() == 1 << 40


def test_zero_vertices_declared_pass_the_budget():
    Budget(10).vertices(0, "the header")
    with pytest.raises(InvalidMeshError, match="^the file is corrupt: the header declares a negative count$"):
        Budget(10).vertices(-1, "the header")


def test_vertices_up_to_exactly_the_raw_factor_times_the_limit_pass():
    Budget(10).vertices(RAW_VERTEX_FACTOR * 10, "the header")
    with pytest.raises(InvalidMeshError) as info:
        Budget(10).vertices(RAW_VERTEX_FACTOR * 10 + 1, "the header")
    assert str(info.value) == (
        "the header declares 61 vertices: far more than the limit of 10 vertices could hold even after"
        " welding duplicates"
    )
