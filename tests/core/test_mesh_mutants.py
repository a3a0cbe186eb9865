"""load_mesh's refusals, word for word (issue 15 mutation pass)."""

from __future__ import annotations

import pytest

from app.core.mesh import InvalidMeshError, load_mesh

TETRA_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def _message(*args, **kwargs) -> str:
    with pytest.raises(InvalidMeshError) as info:
        load_mesh(*args, **kwargs)
    return str(info.value)


def test_bytes_without_a_file_type_are_refused_in_words():
    assert _message(TETRA_OBJ) == "the mesh format is unknown: give a file name with an extension"


def test_an_empty_file_is_refused_in_words():
    assert _message(b"", "obj") == "the file is empty"


def test_a_mesh_over_the_vertex_limit_after_welding_says_both_numbers():
    assert load_mesh(TETRA_OBJ, "obj", max_vertices=4).n_vertices == 4  # at the limit
    assert _message(TETRA_OBJ, "obj", max_vertices=3) == (
        "the mesh has 4 vertices once duplicates are welded, more than the limit of 3"
    )
