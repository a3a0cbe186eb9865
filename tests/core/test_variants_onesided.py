"""Re-triangulated by one-sided evidence: a coarser copy whose vertices lie on the original surface
(a decimation, a remesh that dropped a thin part) against shapes of one kind that differ."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import trimesh

from app.core.mesh import Mesh, load_mesh
from app.core.variants import Prepared, relate
from app.core.variants.onesided import (
    COVER_FLOOR,
    COVER_TOL,
    FULL_COARSENING,
    MIN_VERTICES,
    RESOLUTION_CAP,
    VERTEX_FLOOR,
    VERTEX_MAX,
    VERTEX_MAX_FLOOR,
    VERTEX_TOL,
    lies_on,
    mean_edge,
    side,
    slack,
)
from tests.conftest import dataset_or_skip


def _torus(
    major: int, minor: int, tube: float = 0.3, spike: bool = False, turn: np.ndarray | None = None
) -> Mesh:
    """A tilted torus (vertices on the exact surface whatever the sections); `spike`: a thin rod
    (radius 0.03, 1.3 % of the area) stuck into its outer side, far out of the ring."""
    t = trimesh.creation.torus(1.0, tube, major_sections=major, minor_sections=minor)
    v, f = np.asarray(t.vertices) * [1.0, 1.0, 0.8], np.asarray(t.faces, np.int64)
    if spike:
        rod = trimesh.creation.cylinder(radius=0.03, height=0.9, sections=12)
        rv = np.asarray(rod.vertices)[:, [2, 1, 0]] + [1.55, 0.0, 0.0]
        v, f = np.vstack([v, rv]), np.vstack([f, np.asarray(rod.faces, np.int64) + len(v)])
    v[:, 2] += 0.3 * v[:, 0]  # a shear: no symmetry plane, distinct principal axes
    return Mesh(v if turn is None else v @ turn.T, f)


@pytest.fixture(scope="module")
def fine() -> Prepared:
    return Prepared(_torus(96, 32, spike=True))


def test_slack_grows_with_the_coarsening() -> None:
    assert slack(0.1, 0.1) == 0.0 and slack(0.1, 0.2) == 0.0  # no coarser: no slack
    assert slack(0.1, 0.1 / (1 + 0.5 * (FULL_COARSENING - 1))) == pytest.approx(0.05)  # halfway
    assert slack(0.1, 0.01) == pytest.approx(0.1)  # a decimation to a tenth: the whole edge
    assert slack(0.5, 0.01) == pytest.approx(RESOLUTION_CAP)  # a few huge triangles buy no more


def test_side_by_hand() -> None:
    """Margins are the gaps over the tolerances: slack-scaled, or the floors when that is smaller."""
    vertex = np.array([0.0] * 98 + [0.02, 0.03])  # (100,): largest 0.03
    other = np.linspace(0.0, 0.1, 11)  # 90 % quantile 0.09
    e, s, gap, uncovered, margin = side(vertex, other, edge=0.5, other_edge=0.05)
    assert (e, s) == (0.5, pytest.approx(RESOLUTION_CAP))
    assert gap == pytest.approx(np.quantile(vertex, 0.99)) and uncovered == pytest.approx(0.09)
    expected = max(gap / (VERTEX_TOL * s), 0.03 / (VERTEX_MAX * s), 0.09 / (COVER_TOL * s))
    assert margin == pytest.approx(expected)
    *_, same = side(vertex, other, edge=0.05, other_edge=0.05)  # same resolution: the floors
    assert same == pytest.approx(max(gap / VERTEX_FLOOR, 0.03 / VERTEX_MAX_FLOOR, 0.09 / COVER_FLOOR))
    *_, few = side(vertex[:MIN_VERTICES - 1], other, edge=0.5, other_edge=0.05)
    assert few == float("inf")  # a box's 8 corners lie on anything blocky: too few to say
    on = lies_on(vertex, other, 0.5, vertex * 10, other * 10, 0.05)  # the b side is ten times worse
    assert on.a_on_b and on.margin == pytest.approx(margin)
    assert not lies_on(vertex * 10, other * 10, 0.05, vertex, other, 0.5).a_on_b


def test_mean_edge_of_a_unit_square() -> None:
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    square = Mesh(corners, np.array([[0, 1, 2], [0, 2, 3]]))
    assert mean_edge(square) == pytest.approx((4 + 2 * np.sqrt(2)) / 6)


@pytest.mark.parametrize("sections", [(16, 8), (12, 6)])
def test_coarse_copy_that_dropped_a_thin_part_is_retriangulated(fine, random_rotation, sections) -> None:
    """Its vertices lie on the original; the rod it lost is far out (the symmetric Hausdorff distance
    fails) but a small part of the area."""
    coarse = _torus(*sections, turn=random_rotation(6))
    ev = relate(Prepared(coarse), fine)
    assert ev.hausdorff > 0.06  # the symmetric test alone says no
    assert ev.relation == "retriangulated" and ev.lies_on_other is True
    assert ev.vertex_gap is not None and ev.vertex_gap < 0.02
    assert ev.resolution is not None and ev.resolution > 0.05
    assert 0.5 < ev.confidence < 1.0
    back = relate(fine, Prepared(coarse))  # seen from the original: the other one lies on it
    assert back.relation == "retriangulated" and back.lies_on_other is False


@pytest.mark.parametrize("sections", [(96, 32), (16, 8)])
def test_same_kind_different_shape_is_only_similar(fine, sections, monkeypatch) -> None:
    """A ring 27 % thinner (with its rod, or coarse without) is not the same surface at any of these
    resolutions: its vertices are 3-4 % of the diagonal inside the original. The gate's fingerprint
    boxes may rule it out first; with them opened, the one-sided test says so."""
    thins = [Prepared(_torus(*sections, tube=0.22)), Prepared(_torus(*sections, tube=0.22, spike=True))]
    for thin in thins:
        assert relate(thin, fine).relation == "similar"
    gate = importlib.import_module("app.core.variants.gate")
    monkeypatch.setattr(gate, "SAME_BOX", np.full(17, np.inf))
    monkeypatch.setattr(gate, "COARSE_BOX", np.full(17, np.inf))
    for thin in thins:
        ev = relate(thin, fine)
        assert ev.relation == "similar" and not ev.screened, ev
        assert ev.vertex_gap is not None and ev.vertex_gap > 0.03


@pytest.mark.parametrize("fraction", [0.5, 0.1])
def test_decimated_shrec_mesh_is_retriangulated(fraction) -> None:
    from benchmarks.variants_detect_kinds import decimate

    path = sorted((dataset_or_skip("shrec11-simplified") / "hand").rglob("*.obj"))[0]
    base = load_mesh(path)
    ev = relate(Prepared(decimate(base, fraction)), Prepared(base))
    assert ev.relation == "retriangulated"


def test_two_poses_of_a_laptop_are_not_variants() -> None:
    """The closest pair of one SHREC'11 class measured (a laptop opened further): most vertices of one
    lie on the other, but a tenth of the other surface is more than 0.6 edge lengths away."""
    root = dataset_or_skip("shrec11-simplified") / "laptop"
    files = {p.name: p for p in root.rglob("*.obj")}
    base = sorted(files.values())[0]
    ev = relate(Prepared(load_mesh(files["T313.obj"])), Prepared(load_mesh(base)))
    assert ev.relation == "similar"


@pytest.mark.parametrize("seeds", [(5, 9), (7, 8), (5, 7)])
def test_two_coarse_blobs_at_one_resolution_are_only_similar(seeds) -> None:
    """Convex hulls of 80 random points (about 20 vertices, edges a third of the diagonal): each one's
    vertices are within 0.3 edge lengths of the other's surface, which a tolerance proportional to the
    edge alone would accept; neither is coarser than the other, so the floors apply."""

    def hull(seed: int) -> Mesh:
        tm = trimesh.convex.convex_hull(np.random.default_rng(seed).normal(size=(80, 3)) * [1.0, 0.6, 0.35])
        return Mesh(np.asarray(tm.vertices), np.asarray(tm.faces, np.int64))

    ev = relate(Prepared(hull(seeds[0])), Prepared(hull(seeds[1])))
    assert ev.relation == "similar"
    assert ev.slack is not None and ev.vertex_gap is not None and ev.vertex_gap > 0.015


def test_cover_margin_by_hand_and_as_a_lower_bound_of_the_side_margin() -> None:
    from app.core.variants.onesided import COVER_FLOOR, COVER_TOL, cover_margin, side, slack

    other = np.linspace(0.0, 0.1, 101)  # its 90 % quantile is 0.09
    assert cover_margin(other, 0.05, 0.05) == pytest.approx(0.09 / COVER_FLOOR)  # no coarser: the floor
    s = slack(0.3, 0.1)  # edges 3 times the other's: the capped edge is all slack
    assert s == pytest.approx(0.15)
    assert cover_margin(other, 0.3, 0.1) == pytest.approx(0.09 / max(COVER_FLOOR, COVER_TOL * s))
    vertices = np.full(50, 0.001)  # vertices on the surface: the coverage term is the whole margin
    assert side(vertices, other, 0.05, 0.05)[4] == pytest.approx(cover_margin(other, 0.05, 0.05))
    far = np.full(50, 0.2)  # vertices off the surface raise the margin above the bound
    assert side(far, other, 0.05, 0.05)[4] > cover_margin(other, 0.05, 0.05)


@pytest.mark.parametrize("subdivisions", [0, 1, 3])
def test_distance_to_surface_is_the_exact_point_to_triangle_distance(subdivisions: int) -> None:
    """Against every face by brute force: a coarse mesh (many repeated candidate faces per point) and
    a fine one, points on, inside and outside the surface."""
    from app.core.variants.surface import closest_on_triangles

    tm = trimesh.creation.icosphere(subdivisions=subdivisions)
    mesh = Mesh(np.asarray(tm.vertices), np.asarray(tm.faces, np.int64))
    rng = np.random.default_rng(subdivisions)
    directions = rng.standard_normal((300, 3))
    points = directions / np.linalg.norm(directions, axis=1)[:, None] * rng.uniform(0.8, 1.2, (300, 1))
    got = Prepared(mesh).distance_to(points)
    v, f = mesh.vertices, mesh.faces
    p = np.repeat(points, len(f), axis=0)
    tiled = np.tile(f, (len(points), 1))
    near = closest_on_triangles(p, v[tiled[:, 0]], v[tiled[:, 1]], v[tiled[:, 2]])
    expected = np.linalg.norm(near - p, axis=1).reshape(len(points), len(f)).min(axis=1)
    assert got.shape == (300,)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert got.max() > 0.1  # the points are off the surface, not only on it


def test_a_direction_skipped_on_its_coverage_leaves_the_decision_as_the_full_test_gives_it() -> None:
    """_evidence(decide=d) measures the one-sided test only where the symmetric margin reaches d, and a
    direction of it only when its coverage alone is under d: on spheres, ellipsoids and a capsule at
    several resolutions, in place, every `similar` decision at d is the full test's, and a pair it
    still calls retriangulated has the full test's evidence."""
    from app.core.variants.align import Similarity

    r = importlib.import_module("app.core.variants.relate")

    def prepared(tm: trimesh.Trimesh) -> Prepared:
        return Prepared(Mesh(np.asarray(tm.vertices, float), np.asarray(tm.faces, np.int64)))

    shapes = [prepared(trimesh.creation.icosphere(1)), prepared(trimesh.creation.icosphere(3)),
              prepared(trimesh.creation.icosphere(3).apply_scale(1.08)),
              prepared(trimesh.creation.icosphere(3).apply_scale([1.0, 1.0, 0.8])),
              prepared(trimesh.creation.icosphere(1).apply_scale([1.15, 1.0, 0.85])),
              prepared(trimesh.creation.capsule(1.0, 0.8))]
    in_place = Similarity(1.0, np.eye(3), np.zeros(3))
    skipped = undecided = 0
    for a in shapes:
        for b in shapes:
            if a is b:
                continue
            full = r._evidence(a, b, in_place, points=256)
            for decide in (2.0, 4.0):
                fast = r._evidence(a, b, in_place, points=256, decide=decide)
                at = 1.0 - 0.5 / decide
                decided = [e.relation == "similar" and e.confidence >= at for e in (fast, full)]
                assert decided[0] == decided[1]
                if fast.relation == "retriangulated":
                    assert fast == full
                skipped += fast.confidence != full.confidence
                undecided += not decided[0] and fast.lies_on_other is None and full.lies_on_other is not None
    assert skipped >= 4 and undecided >= 2  # work was skipped, on decided and undecided pairs
