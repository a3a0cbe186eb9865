"""The invariant gate before any alignment (app/core/variants/gate.py): the thresholds by hand, pairs it
must rule out without a fit, and true variants it must let through."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import trimesh

from app.core.mesh import Mesh
from app.core.variants import Prepared, relate
from app.core.variants.gate import (
    COARSE_BOX,
    COARSE_RATIO,
    RADIUS,
    SAME_BOX,
    SAME_RADIUS,
    coarsening,
    may_relate,
)
from tests.variant_meshes import hull_trimesh

G = importlib.import_module("app.core.variants.gate")
R = importlib.import_module("app.core.variants.relate")


def _prepared(tm: trimesh.Trimesh) -> Prepared:
    return Prepared(Mesh(np.asarray(tm.vertices, float), np.asarray(tm.faces, np.int64)))


def _posed(fingerprint: np.ndarray, resolution: float, vertices: int = 100) -> Prepared:
    """A Prepared whose fingerprint and resolution are set by hand (cached properties are plain
    attributes once set), on a mesh of `vertices` vertices."""
    p = Prepared(Mesh(np.zeros((vertices, 3)), np.array([[0, 1, 2]])))
    p.fingerprint = np.asarray(fingerprint, np.float32)
    p.resolution = resolution
    return p


def test_thresholds_by_hand() -> None:
    base = np.zeros(17)
    same = SAME_BOX / np.linalg.norm(SAME_BOX)  # unit steps spread like a true variant's gaps
    coarse = COARSE_BOX / np.linalg.norm(COARSE_BOX)
    a = _posed(base, 0.05)
    assert may_relate(a, _posed(base + 0.9 * SAME_RADIUS * same, 0.05))  # near: always verified
    # past SAME_RADIUS at one resolution: no relation is possible
    assert not may_relate(a, _posed(base + 1.1 * SAME_RADIUS * same, 0.05 * 0.9 * COARSE_RATIO))
    # ... unless one is much coarser (and has enough vertices to lie on the other)
    assert may_relate(a, _posed(base + 1.1 * SAME_RADIUS * coarse, 0.05 * 1.1 * COARSE_RATIO))
    assert may_relate(_posed(base, 0.05 * 1.1 * COARSE_RATIO), _posed(base + 0.99 * RADIUS * coarse, 0.05))
    assert not may_relate(a, _posed(base + 1.1 * SAME_RADIUS * coarse, 0.05 * 3 * COARSE_RATIO, vertices=19))
    assert not may_relate(a, _posed(base + 1.01 * RADIUS * coarse, 0.05 * 3 * COARSE_RATIO))  # too far
    assert coarsening(a, _posed(base, 0.2)) == pytest.approx(4.0)
    assert coarsening(_posed(base, 0.2), a) == pytest.approx(4.0)  # symmetric


def test_each_entry_within_its_box() -> None:
    """Well within both radii, but one entry past its bound: ruled out; the same gap on an entry
    that allows it: verified. A much coarser copy gets the wider box."""
    base = np.zeros(17)
    a = _posed(base, 0.05)
    low_d2 = np.eye(17)[12]  # the D2 10 % quantile: sampling noise moves it by 0.046 at most
    area = np.eye(17)[2]  # trace / area: noise and decimation move it most
    assert SAME_BOX[12] < 0.08 < 0.2 * SAME_RADIUS and SAME_BOX[2] > 0.4  # the premises
    # (trace / area moved a little too: the exact entries differ, so the same triangles are ruled out)
    assert not may_relate(a, _posed(base + 0.08 * low_d2 + 0.01 * area, 0.05))
    assert may_relate(a, _posed(base + 0.4 * area, 0.05))
    assert not may_relate(a, _posed(base + 0.6 * area, 0.05))  # inside SAME_RADIUS, outside its box
    assert SAME_BOX[2] < 0.6 <= COARSE_BOX[2]
    assert may_relate(a, _posed(base + 0.6 * area, 0.05 * 1.1 * COARSE_RATIO))
    assert np.all(COARSE_BOX >= SAME_BOX)


def test_resolution_is_free_of_scale_and_pose() -> None:
    torus = trimesh.creation.torus(1.0, 0.3, major_sections=24, minor_sections=12)
    moved = torus.copy()
    moved.apply_transform(trimesh.transformations.random_rotation_matrix(np.random.default_rng(3).random(3)))
    moved.apply_scale(25.4)
    assert _prepared(moved).resolution == pytest.approx(_prepared(torus).resolution, rel=1e-9)


def test_must_not_match_pairs_are_ruled_out_without_a_fit(monkeypatch) -> None:
    """A torus and a capsule at about one resolution, fingerprints 0.88 apart; a torus and a 17-vertex
    hull (much coarser, but too few vertices to lie on anything): `similar`, no ICP run."""
    fits: list[int] = []
    real = R.icp_batch
    monkeypatch.setattr(R, "icp_batch", lambda *a, **k: fits.append(1) or real(*a, **k))
    torus = _prepared(trimesh.creation.torus(1.0, 0.3, major_sections=48, minor_sections=24))
    capsule = _prepared(trimesh.creation.capsule(height=1.0, radius=0.5, count=[24, 24]))
    hull = _prepared(hull_trimesh(7))
    gap = float(np.linalg.norm(torus.fingerprint - capsule.fingerprint))
    assert SAME_RADIUS < gap <= RADIUS and coarsening(torus, capsule) < COARSE_RATIO  # the premises
    assert hull.mesh.n_vertices < G.MIN_VERTICES and coarsening(torus, hull) > COARSE_RATIO
    for a, b in ((torus, capsule), (capsule, torus), (torus, hull), (hull, torus)):
        ev = relate(a, b)
        assert ev.relation == "similar" and ev.screened and np.isnan(ev.chamfer)
    assert not fits


def test_true_variants_are_let_through(monkeypatch) -> None:
    """A coarse icosphere (42 vertices) on a fine one (2,562): near in fingerprint, and let through by
    the coarse route alone too (SAME_RADIUS set to 0): re-triangulated either way. A subdivided hull
    (the same surface) is near and kept."""
    fine = _prepared(trimesh.creation.icosphere(subdivisions=4))
    coarse = _prepared(trimesh.creation.icosphere(subdivisions=1))
    assert relate(coarse, fine).relation == "retriangulated"
    monkeypatch.setattr(G, "SAME_RADIUS", 0.0)
    assert coarsening(coarse, fine) > COARSE_RATIO and may_relate(coarse, fine)
    ev = relate(coarse, fine)
    assert ev.relation == "retriangulated" and not ev.screened
    hull = hull_trimesh(8)
    finer = hull.subdivide()
    monkeypatch.setattr(G, "SAME_RADIUS", SAME_RADIUS)
    assert relate(_prepared(finer), _prepared(hull)).relation == "retriangulated"


def test_a_pair_decided_by_its_objects_is_not_called_screened() -> None:
    """A hull against a plate of five other hulls: the whole surfaces are ruled out by the gate, the
    objects are verified and none matches: `similar` with the numbers of an object pair, not the
    gate's NaNs."""
    from tests.variant_meshes import hull, plate

    small, big = Prepared(hull(7)), Prepared(plate([hull(s) for s in (20, 21, 22, 23, 24)]))
    assert not may_relate(small, big) and any(may_relate(small, o) for o in big.parts)  # the premises
    for ev in (relate(small, big), relate(big, small)):
        assert ev.relation == "similar" and not ev.screened and np.isfinite(ev.chamfer)


def test_fingerprint_rows_screen_implies_the_gate_answer() -> None:
    """may_relate_any on the stored fingerprints (whole + objects) says False only where relate() can
    answer nothing but the gate's `similar`: a torus and a box (within the radius, outside the box);
    a hull and a plate holding it pass (through an object), as do a hull and its coarse copy."""
    from app.core.variants.collection import fingerprints
    from app.core.variants.gate import may_relate_any
    from tests.variant_meshes import hull, plate

    box = _prepared(trimesh.creation.box(extents=[1, 2, 3]).subdivide().subdivide())
    torus = _prepared(trimesh.creation.torus(1.0, 0.3, major_sections=48, minor_sections=24))
    assert np.linalg.norm(torus.fingerprint - box.fingerprint) <= RADIUS  # the premise: a lookup finds it
    assert not may_relate_any(fingerprints(torus), fingerprints(box))
    assert relate(torus, box).screened and relate(box, torus).screened
    part = Prepared(hull(7))
    on_plate = Prepared(plate([hull(20), hull(7), hull(21)]))
    assert may_relate_any(fingerprints(part), fingerprints(on_plate))
    assert relate(part, on_plate).relation == "part_of"
    fine = _prepared(trimesh.creation.icosphere(subdivisions=4))
    coarse = _prepared(trimesh.creation.icosphere(subdivisions=1))
    assert may_relate_any(fingerprints(coarse), fingerprints(fine))
    others = [_prepared(hull_trimesh(s)) for s in range(30, 36)] + [box, torus, fine, coarse, part, on_plate]
    for a in others:  # whenever the screen says no, relate says the gate's unmeasured `similar`
        for b in others:
            if a is not b and not may_relate_any(fingerprints(a), fingerprints(b)):
                assert relate(a, b).screened


def test_equal_exact_entries_let_sampling_noise_through() -> None:
    """Entries 0-6 are exact integrals: equal there (to EXACT_MATCH), a pair may have the same
    triangles and is verified whatever its sampled entries say, within the radius only."""
    base = np.full(17, 0.5)
    a = _posed(base, 0.05)
    sampled = np.zeros(17)
    sampled[7:] = 0.09  # past SAME_BOX on several sampled entries, L2 0.28
    assert np.any(sampled > SAME_BOX) and np.linalg.norm(sampled) < SAME_RADIUS  # the premises
    assert may_relate(a, _posed(base + sampled, 0.05))
    assert may_relate(a, _posed(base + sampled + 0.5 * G.EXACT_MATCH * np.eye(17)[0], 0.05))
    assert not may_relate(a, _posed(base + sampled + 2.0 * G.EXACT_MATCH * np.eye(17)[0], 0.05))
    far = np.zeros(17)
    far[7:] = 0.33  # L2 1.04: past the radius, exact entries or not
    assert not may_relate(a, _posed(base + far, 0.05))
    from app.core.variants.gate import may_relate_any

    assert may_relate_any(base[None] + sampled, base[None])
    assert not may_relate_any(base[None] + sampled + 2.0 * G.EXACT_MATCH * np.eye(17)[0], base[None])


def test_boxes_are_no_narrower_than_the_sampling_noise() -> None:
    assert np.all(SAME_BOX >= G.NOISE_FLOOR) and np.all(COARSE_BOX >= G.NOISE_FLOOR)
    assert np.all(G.NOISE_FLOOR[: G.EXACT_ENTRIES] == 0)  # exact integrals carry no sampling noise
    assert np.all(SAME_BOX >= G._SAME_SEEN) and np.all(COARSE_BOX >= G._COARSE_SEEN)


def test_faces_in_another_order_keep_the_exact_entries_and_are_found_identical() -> None:
    """The same torus, faces in another order: entries 0-6 equal to rounding, the sampled ones moved
    (here past the bound the two benchmark samples alone gave the D2 10 % quantile); identical."""
    tm = trimesh.creation.torus(1.0, 0.1, major_sections=32, minor_sections=8)
    mesh = Mesh(np.asarray(tm.vertices, float), np.asarray(tm.faces, np.int64))
    other = Mesh(mesh.vertices, mesh.faces[np.random.default_rng(18).permutation(mesh.n_faces)])
    a, b = Prepared(other), Prepared(mesh)
    diff = np.abs(a.fingerprint - b.fingerprint)
    assert np.all(diff[: G.EXACT_ENTRIES] <= 1e-6)
    assert np.any(diff > G._SAME_SEEN)  # the premise: the old boxes ruled this copy out
    assert may_relate(a, b)
    ev = relate(a, b)
    assert ev.relation == "identical" and not ev.screened


def test_the_same_triangles_in_another_winding_are_verified() -> None:
    """Some faces flipped: the signed volume (entry 3) moves, the triangles are the same; the gate
    lets the pair through and relate finds it identical (triangles are compared as vertex sets)."""
    b = _prepared(hull_trimesh(11))
    faces = b.mesh.faces.copy()
    faces[::3] = faces[::3, ::-1]
    a = Prepared(Mesh(b.mesh.vertices, faces))
    diff = np.abs(a.fingerprint - b.fingerprint)
    assert diff[3] > SAME_BOX[3] and np.all(diff[G.WINDING_FREE] <= G.EXACT_MATCH)  # the premises
    assert may_relate(a, b) and relate(a, b).relation == "identical"
