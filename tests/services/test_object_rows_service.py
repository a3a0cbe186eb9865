"""app.services.object_rows: a file's objects described within their budget, never failing the file."""

from __future__ import annotations

import time

import numpy as np
import trimesh

from app.core.meshdata import InvalidMeshError, Mesh
from app.core.pipeline import DescribeParams
from app.services import object_rows


def _plate() -> Mesh:
    parts = [trimesh.creation.box((1.0, 0.3 + 0.3 * i, 0.5)).subdivide().subdivide() for i in range(3)]
    for i, p in enumerate(parts):
        p.apply_translation([3.0 * i, 0.0, 0.0])
    joined = trimesh.util.concatenate(parts)
    return Mesh(np.asarray(joined.vertices, np.float64), np.asarray(joined.faces, np.int64))


def test_no_object_is_started_past_the_budget(monkeypatch):
    calls: list[int] = []

    def slow(mesh, params):
        calls.append(mesh.n_faces)
        time.sleep(0.2)
        return object()

    monkeypatch.setattr(object_rows, "describe", slow)
    params = DescribeParams()
    assert len(object_rows.describe_objects(_plate(), params, 8)) == 3
    calls.clear()
    found = object_rows.describe_objects(_plate(), params, 8, budget_s=0.1)
    assert len(found) == len(calls) == 1  # the first started at once; past 0.1 s no other was
    assert object_rows.describe_objects(_plate(), params, 0) == []  # SHAPEBAG_OBJECT_ROWS=0


def test_an_object_that_cannot_be_described_is_left_out_and_the_others_kept(monkeypatch):
    def picky(mesh, params):
        if len(seen) == 1:
            seen.append(mesh.n_faces)
            raise InvalidMeshError("the mesh's Laplace-Beltrami spectrum could not be computed")
        seen.append(mesh.n_faces)
        return object()

    seen: list[int] = []
    monkeypatch.setattr(object_rows, "describe", picky)
    found = object_rows.describe_objects(_plate(), DescribeParams(), 8)
    assert [o.row.part for o in found] == [1, 3] and len(seen) == 3
