"""The partial benchmark: kept fractions in the band and true to the area, one piece, seeded, open."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import trimesh

from app.core.cleaning import vertex_components
from app.core.holes import boundary_loops
from app.core.mesh import Mesh, load_mesh
from benchmarks.partial import cut, face_areas, generate, largest_piece, parse_band, punch, scan, visible

BANDS = [(0.60, 0.85), (0.40, 0.60)]


def _sphere() -> Mesh:
    s = trimesh.creation.icosphere(subdivisions=3)
    return Mesh(np.asarray(s.vertices, np.float64), np.asarray(s.faces, np.int64))


def _capsule() -> Mesh:
    s = trimesh.creation.capsule(height=2.0, radius=0.5, count=[24, 24])
    s.merge_vertices()
    return Mesh(np.asarray(s.vertices, np.float64), np.asarray(s.faces, np.int64))


def test_face_areas_sum_to_the_trimesh_area() -> None:
    m = _capsule()
    assert face_areas(m).sum() == pytest.approx(trimesh.Trimesh(m.vertices, m.faces).area, rel=1e-12)
    unit = Mesh(np.array([[0.0, 0, 0], [2, 0, 0], [0, 3, 0]]), np.array([[0, 1, 2]]))
    assert face_areas(unit)[0] == pytest.approx(3.0)


@pytest.mark.parametrize("band", BANDS)
@pytest.mark.parametrize("cuts", [1, 2])
@pytest.mark.parametrize("make", [_sphere, _capsule])
def test_cut_keeps_one_piece_with_the_true_fraction_in_band(make, cuts: int, band) -> None:
    mesh = make()
    piece, fraction = cut(mesh, band, np.random.default_rng(3), cuts)
    assert band[0] <= fraction <= band[1]
    whole = trimesh.Trimesh(mesh.vertices, mesh.faces).area
    assert trimesh.Trimesh(piece.vertices, piece.faces).area / whole == pytest.approx(fraction, abs=1e-9)
    assert len(np.unique(vertex_components(piece))) == 1
    # a plane cut opens a closed surface: one rim per plane at most, at least one
    assert 1 <= len(boundary_loops(piece.faces, piece.n_vertices)) <= cuts


def test_one_cut_is_a_half_space() -> None:
    """Every kept face lies on one side of some plane, the removed faces of the sphere on the other."""
    mesh = _sphere()
    piece, _ = cut(mesh, (0.6, 0.85), np.random.default_rng(0), 1)
    # the piece's rim is planar up to one triangle: its vertices fit a plane within an edge length
    rim = boundary_loops(piece.faces, piece.n_vertices)[0]
    pts = piece.vertices[rim] - piece.vertices[rim].mean(axis=0)
    edge = np.linalg.norm(mesh.vertices[mesh.faces[0, 0]] - mesh.vertices[mesh.faces[0, 1]])
    assert np.linalg.svd(pts, compute_uv=False)[-1] / np.sqrt(len(rim)) < edge


@pytest.mark.parametrize("band", BANDS)
def test_holes_open_the_surface_and_keep_the_band(band) -> None:
    mesh = _sphere()
    piece, fraction = punch(mesh, band, np.random.default_rng(5))
    assert band[0] <= fraction <= band[1]
    assert face_areas(piece).sum() / face_areas(mesh).sum() == pytest.approx(fraction, abs=1e-9)
    assert len(np.unique(vertex_components(piece))) == 1
    assert boundary_loops(mesh.faces, mesh.n_vertices) == []
    assert len(boundary_loops(piece.faces, piece.n_vertices)) >= 1


def _folder(root: Path) -> Path:
    src = root / "src"
    src.mkdir()
    rows = []
    for i, (name, make) in enumerate([("ball", _sphere), ("pill", _capsule)] * 2):
        m = make()
        trimesh.Trimesh(m.vertices * (1 + i), m.faces).export(src / f"{name}{i}.obj")
        rows.append(f"{name}{i}.obj,{name}\n")
    (src / "labels.csv").write_text("file,class\n" + "".join(rows))
    return src


@pytest.mark.parametrize("holes", [False, True])
def test_generate_writes_labels_and_fractions_reproducibly(tmp_path: Path, holes: bool) -> None:
    src = _folder(tmp_path)
    a = generate(src, tmp_path / "a", (0.6, 0.85), cuts=2, holes=holes, seed=1)
    b = generate(src, tmp_path / "b", (0.6, 0.85), cuts=2, holes=holes, seed=1)
    c = generate(src, tmp_path / "c", (0.6, 0.85), cuts=2, holes=holes, seed=2)
    table = list(csv.DictReader((a / "partial.csv").open()))
    labels = list(csv.DictReader((a / "labels.csv").open()))
    assert [(r["file"], r["class"]) for r in table] == [(r["file"], r["class"]) for r in labels]
    assert len(table) == 4 and {r["cuts"] for r in table} == {"0" if holes else "2"}
    for r in table:
        whole = load_mesh(src / r["file"])
        part = load_mesh(a / r["file"])
        assert 0.6 <= float(r["kept_fraction"]) <= 0.85
        assert face_areas(part).sum() / face_areas(whole).sum() == pytest.approx(float(r["kept_fraction"]),
                                                                                 abs=2e-4)
        assert (a / r["file"]).read_bytes() == (b / r["file"]).read_bytes()
    assert (a / "partial.csv").read_bytes() == (b / "partial.csv").read_bytes()
    assert (a / "partial.csv").read_bytes() != (c / "partial.csv").read_bytes()


def test_parse_band() -> None:
    assert parse_band("60-85") == (0.60, 0.85)
    with pytest.raises(ValueError):
        parse_band("85-60")


def test_a_sliver_is_an_empty_piece_not_an_error() -> None:
    mesh = _sphere()
    keep = np.zeros(len(mesh.faces), dtype=bool)
    keep[0] = True
    assert len(largest_piece(mesh, keep).faces) == 0


def test_a_viewer_sees_half_a_sphere_and_nothing_behind_a_wall() -> None:
    """From far along +z a sphere shows the faces of its upper half (its area's half); a second sphere
    straight below it is hidden, one beside it is seen as the first."""
    ball = _sphere()
    up = np.array([0.0, 0.0, 1.0])
    seen = visible(ball, up)
    areas = face_areas(ball)
    assert areas[seen].sum() / areas.sum() == pytest.approx(0.5, abs=0.03)
    centroids = ball.vertices[ball.faces].mean(axis=1)
    assert (centroids[seen, 2] > -0.05).all() and (centroids[~seen, 2] < 0.05).all()
    n = len(ball.vertices)
    for offset, hidden in (([0.0, 0.0, -3.0], True), ([3.0, 0.0, 0.0], False)):
        pair = Mesh(np.vstack([ball.vertices, ball.vertices + offset]),
                    np.vstack([ball.faces, ball.faces + n]))
        lower = visible(pair, up)[len(ball.faces):]
        # (the faces on the silhouette, where a polygonal sphere's two outlines differ, either way)
        if hidden:
            assert lower.sum() < 0.03 * len(lower)
        else:
            assert abs(int(lower.sum()) - int(seen.sum())) < 0.03 * len(lower)


def test_scans_keep_the_band_and_more_views_see_more() -> None:
    rng = np.random.default_rng(3)
    shape = _capsule()
    total = face_areas(shape).sum()
    piece, fraction = scan(shape, (0.40, 0.60), rng, 1)
    assert 0.40 <= fraction <= 0.60
    assert face_areas(piece).sum() / total == pytest.approx(fraction, abs=2e-4)
    assert len(boundary_loops(piece.faces, piece.n_vertices)) >= 1  # open: a one-sided scan
    wider, more = scan(shape, (0.60, 0.95), rng, 3)
    assert more > fraction
