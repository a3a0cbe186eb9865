"""Readers count a scene's expansion from its declarations before building it (app/core/formats/graph.py):
hand-computed totals on small graphs, and each generated structure bomb refused in milliseconds with
words that name the problem, while the same structures at a small size are read exactly."""

from __future__ import annotations

import time

import numpy as np
import pytest

from app.core.formats import graph
from app.core.mesh import InvalidMeshError, _parse, load_mesh
from app.core.meshdata import Budget
from tests.reliability import hostile as h

T = graph.Totals


def test_expand_counts_every_path_of_a_dag_once_per_path():
    # a places b twice and c once; b places c three times; c holds 1 mesh of 4 vertices and 2 faces
    children = {"a": ["b", "b", "c"], "b": ["c", "c", "c"]}
    own = {"c": T(1, 4, 2), "a": T(1, 10, 5)}
    # a: own 1 mesh + 2 * b (3 c each) + 1 c = 1 + 6 + 1 = 8 meshes; vertices 10 + 7 * 4; faces 5 + 7 * 2
    assert graph.expand(["a"], children, own, "test") == T(8, 38, 19)
    assert graph.expand(["a", "c", "c"], children, own, "test") == T(10, 46, 23)


def test_expand_is_exact_on_an_exponential_chain_without_walking_it():
    levels = 60  # 3**59 paths: only a count on the DAG can answer
    children = {k: [k - 1] * 3 for k in range(1, levels)}
    t = time.perf_counter()
    total = graph.expand([levels - 1], children, {0: T(1, 4, 4)}, "chain")
    assert time.perf_counter() - t < 1.0
    assert total == T(3 ** (levels - 1), 4 * 3 ** (levels - 1), 4 * 3 ** (levels - 1))


def test_expand_refuses_cycles_and_deep_chains():
    with pytest.raises(InvalidMeshError, match="cycle"):
        graph.expand(["a"], {"a": ["b"], "b": ["c"], "c": ["a"]}, {}, "test graph")
    with pytest.raises(InvalidMeshError, match="cycle"):
        graph.expand(["a"], {"a": ["a"]}, {}, "test graph")
    deep = {k: [k + 1] for k in range(graph.MAX_DEPTH)}
    with pytest.raises(InvalidMeshError, match=f"more than {graph.MAX_DEPTH} levels"):
        graph.expand([0], deep, {}, "test graph")
    shallow = {k: [k + 1] for k in range(graph.MAX_DEPTH - 2)}
    assert graph.expand([0], shallow, {graph.MAX_DEPTH - 2: T(1, 1, 1)}, "ok") == T(1, 1, 1)


def test_check_holds_placements_and_the_vertex_budget():
    graph.check(T(graph.MAX_PLACEMENTS, 0, 0), "scene", Budget(None))
    with pytest.raises(InvalidMeshError, match=f"places {graph.MAX_PLACEMENTS + 1} meshes"):
        graph.check(T(graph.MAX_PLACEMENTS + 1, 0, 0), "scene", Budget(None))
    with pytest.raises(InvalidMeshError, match="vertices"):
        graph.check(T(1, 10**9, 0), "scene", Budget(1000))


def test_a_3mf_component_graph_is_placed_exactly():
    v, f = _parse(h.two_tetrahedra_3mf(), "3mf")
    assert v.shape == (8, 3) and f.shape == (8, 3)
    expected = np.r_[h.TETRA_V + [0, 0, 10], h.TETRA_V + [3, 0, 10]]
    assert np.allclose(np.sort(v, axis=0), np.sort(expected, axis=0))
    # each copy keeps its own triangles: faces of the second copy point at its own 4 vertices
    assert sorted(map(tuple, np.sort(f[4:], axis=1) - 4)) == sorted(map(tuple, np.sort(h.TETRA_F, axis=1)))
    # a chain of 4 levels of 3 copies places 27 tetrahedra, none dropped
    v, f = _parse(h.component_chain_3mf(4, 3), "3mf")
    assert f.shape == (27 * 4, 3)


def test_small_collada_and_gltf_instances_are_read():
    v, f = _parse(h.instance_node_dae(3, 2), "dae")  # 2 * 2 placements of the tetrahedron
    assert f.shape == (16, 3)
    assert _parse(h.tetrahedron_glb(), "glb")[1].shape == (4, 3)
    zae = h.zip_members({"model.dae": h.tetrahedron_dae()})
    assert load_mesh(zae, "dae").n_faces == 4  # a zipped COLLADA, through the capped reader


# (name, file name, bytes, words the 422 must say)
BOMBS = [
    ("3mf-component-chain", "chain.3mf", h.component_chain_3mf(20, 3), "places 1162261467 meshes"),
    ("3mf-component-cycle", "cycle.3mf", h.component_cycle_3mf(), "cycle"),
    ("3mf-deep-chain", "deep.3mf", h.component_chain_3mf(100, 1), "levels deep"),
    ("dae-instance-node-dag", "dag.dae", h.instance_node_dae(20, 3), "places 1162261467 meshes"),
    ("dae-instance-node-cycle", "cycle.dae", h.instance_node_cycle_dae(), "cycle"),
    (
        "dae-that-is-a-zip-bomb",
        "zipped.dae",
        h.patched_zip({"model.dae": h.tetrahedron_dae()}, declared_size=0x70000000),
        "unpacks to 1879048192 bytes",
    ),
    ("obj-that-is-a-zip", "zipped.obj", h.zip_members({"a.obj": "v 0 0 0\n"}), "is a zip archive"),
    ("zip-version-8.5", "v85.zip", h.patched_zip({"m.glb": h.tetrahedron_glb()}, version=85), "version 8.5"),
    ("3mf-version-8.5", "v85.3mf", h.patched_zip({"3D/3dmodel.model": "x"}, version=85), "version 8.5"),
    ("zip-method-99", "aes.zip", h.patched_zip({"m.glb": h.tetrahedron_glb()}, method=99), "method 99"),
    ("glb-count-1e999", "inf.glb", h.huge_count_glb(), "count is not a whole number"),
    ("glb-float-indices", "float.glb", h.float_index_glb(), "FLOAT"),
    ("glb-shared-children", "shared.glb", h.shared_children_glb(30), "places 1000000001 meshes"),
    ("gltf-120k-nodes", "nodes.zip", h.many_nodes_zip(120_000), "120000 nodes"),
    ("gltf-60k-primitives", "prims.zip", h.many_primitives_zip(60_000), "60000 primitives"),
    ("3mf-billion-laughs", "laughs.3mf", h.billion_laughs_3mf(), "its XML is invalid"),
    ("dae-billion-laughs", "laughs.dae", h.billion_laughs_dae(), "its XML is invalid"),
]


@pytest.mark.parametrize(("case", "filename", "content", "words"), BOMBS, ids=[b[0] for b in BOMBS])
def test_each_structure_bomb_is_refused_from_its_declarations(case, filename, content, words):
    assert len(content) < 32_000, "a hostile file of the corpus is a few kilobytes"
    t = time.perf_counter()
    with pytest.raises(InvalidMeshError, match=words.replace(".", r"\.")):
        load_mesh(content, filename, max_vertices=3000)
    # ms on a quiet machine (python -m benchmarks.hostile_files); the bound leaves room for a busy one
    assert time.perf_counter() - t < 5.0, f"{case} took {time.perf_counter() - t:.2f} s"
