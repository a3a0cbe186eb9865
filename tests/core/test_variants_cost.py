"""The rules that keep the verification cheap: a pair far from any relation on a subsample is decided
there (the fine fit and the full samples are not used), objects are verified only against objects
whose fingerprints are near, a few at most; none of them loses a true relation."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import trimesh

from app.core.mesh import Mesh
from app.core.variants import Prepared, relate
from app.core.variants.gate import may_relate
from app.core.variants.onesided import vertex_subset
from tests.variant_meshes import hull as _hull
from tests.variant_meshes import plate as _plate

R = importlib.import_module("app.core.variants.relate")  # the module, not the function it exports


class Count:
    """Wraps a function of the relate module and records its calls: keywords, and the length of the
    first argument when it is an array (the points an ICP fits)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, name: str) -> None:
        self.calls: list[dict] = []
        real = getattr(R, name)

        def wrapped(*args, **kwargs):
            self.calls.append({**kwargs, "n": len(args[0]) if isinstance(args[0], np.ndarray) else None})
            return real(*args, **kwargs)

        monkeypatch.setattr(R, name, wrapped)


def test_a_pair_far_from_any_relation_is_decided_on_the_subsample(monkeypatch) -> None:
    """Must not match: a torus against a box (within the gate's fingerprint radius, decided quickly
    when the gate's per-entry boxes are opened; with them, no fit at all), two different random
    hulls."""
    box = trimesh.creation.box(extents=[1, 2, 3]).subdivide().subdivide()
    torus = trimesh.creation.torus(1.0, 0.3, major_sections=48, minor_sections=24)
    a, b = (Prepared(Mesh(np.asarray(t.vertices), np.asarray(t.faces, np.int64))) for t in (torus, box))
    assert not may_relate(a, b) and relate(a, b).screened  # the entries' boxes rule it out
    gate = importlib.import_module("app.core.variants.gate")
    monkeypatch.setattr(gate, "SAME_BOX", np.full(17, np.inf))
    monkeypatch.setattr(gate, "COARSE_BOX", np.full(17, np.inf))
    fits = Count(monkeypatch, "icp_batch")
    evidence = Count(monkeypatch, "_evidence")
    assert may_relate(a, b)  # the premise: past the radius test (gate.py), a fit is made
    ev = relate(a, b)
    assert ev.relation == "similar"
    assert ev.confidence >= 1.0 - 0.5 / R.QUICK_MARGIN  # its margin on the subsample
    assert fits.calls and max(c["n"] for c in fits.calls) <= R.QUICK_POINTS  # no fine fit made
    assert [c.get("points") for c in evidence.calls] == [R.QUICK_POINTS]  # the full samples unused
    # two different hulls are nearer than that: verified in full, and still only similar
    assert relate(Prepared(_hull(8)), Prepared(_hull(7))).relation == "similar"


def test_a_true_retriangulation_gets_the_fine_fit_and_the_full_samples(monkeypatch) -> None:
    evidence = Count(monkeypatch, "_evidence")
    fits = Count(monkeypatch, "icp_batch")
    hull = _hull(7)
    v, f = trimesh.remesh.subdivide(hull.vertices, hull.faces)
    ev = relate(Prepared(Mesh(v, f)), Prepared(hull))
    assert ev.relation == "retriangulated" and ev.chamfer < 1e-3
    assert [c.get("points") for c in evidence.calls] == [R.QUICK_POINTS, R.MIDDLE_POINTS, None]
    assert max(c["n"] for c in fits.calls) > R.QUICK_POINTS  # the fine fit was made


def test_a_pair_twice_past_the_tolerances_under_the_fine_fit_is_decided_on_a_quarter(monkeypatch) -> None:
    """Must not match: two random hulls of 200 points, too near for the quick decision; under the fine
    fit, MIDDLE_POINTS samples put them past MIDDLE_MARGIN and the full samples are not measured."""
    evidence = Count(monkeypatch, "_evidence")
    ev = relate(Prepared(_hull(8, n=200)), Prepared(_hull(7, n=200)))
    assert ev.relation == "similar" and ev.confidence >= 1.0 - 0.5 / R.MIDDLE_MARGIN
    assert [c.get("points") for c in evidence.calls] == [R.QUICK_POINTS, R.MIDDLE_POINTS]


def test_objects_far_in_fingerprint_are_not_verified(monkeypatch) -> None:
    """A hull against a plate of a rod and a ball: no object of the plate is near it in fingerprint,
    so no object pair is verified (and the answer is `similar`)."""
    rod = trimesh.creation.cylinder(radius=0.05, height=2.0, sections=24)
    ball = trimesh.creation.icosphere(subdivisions=2)
    plate = _plate([Mesh(np.asarray(t.vertices), np.asarray(t.faces, np.int64)) for t in (rod, ball)])
    small, big = Prepared(_hull(7)), Prepared(plate)
    gaps = [np.linalg.norm(small.fingerprint - o.fingerprint) for o in big.parts]
    assert len(big.parts) == 2 and min(gaps) > R.PART_RADIUS  # the premise of the test
    verified = Count(monkeypatch, "verify")
    assert relate(small, big).relation == "similar"
    # the whole surfaces only, and not even those when the gate (gate.py) rules them out
    assert len(verified.calls) == int(may_relate(small, big))


def test_an_object_is_given_up_after_its_nearest_few(monkeypatch) -> None:
    """A hull against a plate of five other hulls (fingerprints near, none the same): at most
    PART_TRIES of them are verified; the same plate with the hull on it is still `contains`."""
    others = [_hull(s) for s in (20, 21, 22, 23, 24)]
    big = Prepared(_plate(others))
    small = Prepared(_hull(7))
    gaps = [np.linalg.norm(small.fingerprint - o.fingerprint) for o in big.parts]
    assert sum(g <= R.PART_RADIUS for g in gaps) > R.PART_TRIES  # more candidates than are tried
    assert sum(may_relate(small, o) for o in big.parts) > R.PART_TRIES  # ... and past the gate
    verified = Count(monkeypatch, "verify")
    assert relate(small, big).relation == "similar"
    assert len(verified.calls) == int(may_relate(small, big)) + R.PART_TRIES  # the whole, if at all
    ev = relate(Prepared(_plate([*others, _hull(7), _hull(7)])), small)
    assert (ev.relation, ev.copies) == ("contains", 2)


def test_vertex_subset_is_an_even_stride_within_the_limit() -> None:
    mesh = _hull(7, n=400)
    used = np.unique(mesh.faces).size
    assert len(vertex_subset(mesh)) == used  # under MAX_VERTICES: every used vertex
    sub = vertex_subset(mesh, 50)
    assert 25 <= len(sub) <= 50
    assert {tuple(p) for p in sub} <= {tuple(p) for p in mesh.vertices}


def test_vertex_subset_of_the_prepared_used_vertices_is_the_same() -> None:
    mesh = _hull(7, n=400)
    extra = Mesh(np.vstack([mesh.vertices, [[9.0, 9.0, 9.0]]]), mesh.faces)  # an unused vertex
    p = Prepared(extra)
    for limit in (None, 50, 7):
        assert np.array_equal(vertex_subset(extra, limit, p.used_vertices), vertex_subset(extra, limit))
    assert [9.0, 9.0, 9.0] not in p.used_vertices.tolist()


def test_a_pair_of_many_vertices_twice_past_on_the_subsample_is_decided_there(monkeypatch) -> None:
    """Must not match: two random hulls of 1,000 points (38 and 33 vertices) are 2-4 times past the
    tolerances on the quick subsample: both have FIRM_VERTICES or more, so that decides. Two hulls
    of 400 points (20 and 30 vertices) as far past go on to the fine fit (a coarse mesh's quick fit
    may be off its best); both `similar`."""
    evidence = Count(monkeypatch, "_evidence")
    firm = (Prepared(_hull(1, n=1000)), Prepared(_hull(2, n=1000)))
    loose = (Prepared(_hull(1, n=400)), Prepared(_hull(2, n=400)))
    assert min(p.mesh.n_vertices for p in firm) >= R.FIRM_VERTICES  # the premises
    assert min(p.mesh.n_vertices for p in loose) < R.FIRM_VERTICES
    ev = relate(*firm)
    assert ev.relation == "similar"
    assert 1.0 - 0.5 / R.QUICK_MARGIN_FIRM <= ev.confidence < 1.0 - 0.5 / R.QUICK_MARGIN  # 2-4 times past
    assert [c.get("points") for c in evidence.calls] == [R.QUICK_POINTS]
    evidence.calls.clear()
    assert relate(*loose).relation == "similar"
    assert evidence.calls[0].get("points") == R.QUICK_POINTS and len(evidence.calls) > 1  # the fine fit
