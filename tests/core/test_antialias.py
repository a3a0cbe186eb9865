"""The low-pass before decimation (app.core.antialias): a transfer function, invariances, no-ops."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from app.core.antialias import prefilter, ramp_length
from app.core.mesh import Mesh


def _sphere(subdivisions: int = 6) -> Mesh:
    tm = trimesh.creation.icosphere(subdivisions=subdivisions)  # 40,962 vertices at 6, as a scan
    return Mesh(np.asarray(tm.vertices, np.float64), np.asarray(tm.faces, np.int64))


def _bumpy(sphere: Mesh, degree: int, amplitude: float) -> tuple[Mesh, np.ndarray]:
    """The unit sphere with the radial bump amplitude * cos(degree * polar angle): a pattern of
    wavelength ~2*pi/degree (in radii). Returns the mesh and the (n,) bump on the unit sphere."""
    u = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    bump = amplitude * np.cos(degree * np.arccos(np.clip(u[:, 2], -1, 1)))
    return Mesh(u * (1 + bump)[:, None], sphere.faces), bump


def _kept(filtered: Mesh, bump: np.ndarray) -> float:
    """Least-squares factor of the input bump left in the filtered radii (mean radius removed)."""
    r = np.linalg.norm(filtered.vertices, axis=1)
    r, b = r - r.mean(), bump - bump.mean()
    return float(r @ b / (b @ b))


def test_it_passes_what_the_canonical_mesh_can_show_and_stops_what_it_cannot():
    # at 1,000 vertices a unit sphere's edges are ~0.12 radii: a bump of wavelength ~2 radii (degree 3)
    # is well resolved there and must pass; one of wavelength ~0.1 (degree 60) is finer than the
    # canonical mesh's edges and must be damped before decimation aliases it. One implicit step is a
    # first-order low-pass (1 / (1 + t k) at graph frequency k): it damps, it does not cut
    sphere = _sphere()
    low, low_bump = _bumpy(sphere, 3, 0.02)
    high, high_bump = _bumpy(sphere, 60, 0.02)
    assert _kept(prefilter(low, 1000, 0.5), low_bump) > 0.95
    assert _kept(prefilter(high, 1000, 0.5), high_bump) < 0.3
    assert _kept(prefilter(high, 1000, 1.0), high_bump) < 0.1
    # a longer filter stops more of a middling wavelength
    mid, mid_bump = _bumpy(sphere, 20, 0.02)
    assert _kept(prefilter(mid, 1000, 1.0), mid_bump) < _kept(prefilter(mid, 1000, 0.5), mid_bump) < 0.8


def test_vertex_noise_is_removed_and_the_shape_barely_shrinks():
    sphere = _sphere()
    noisy = Mesh(sphere.vertices + np.random.default_rng(0).normal(0, 0.003, sphere.vertices.shape),
                 sphere.faces)
    out = prefilter(noisy, 1000, 0.5)
    radii_in, radii_out = np.linalg.norm(noisy.vertices, axis=1), np.linalg.norm(out.vertices, axis=1)
    assert radii_out.std() < radii_in.std() / 4  # white noise: most of its energy is above the cutoff
    assert abs(radii_out.mean() - 1.0) < 0.005


def test_it_commutes_with_rigid_motion_and_uniform_scale():
    sphere, _ = _bumpy(_sphere(3), 7, 0.05)
    rotation = Rotation.from_euler("xyz", [0.3, -1.1, 2.0]).as_matrix()
    moved = Mesh(3.7 * sphere.vertices @ rotation.T + [5.0, -2.0, 1.0], sphere.faces)
    expected = 3.7 * prefilter(sphere, 300, 0.7).vertices @ rotation.T + [5.0, -2.0, 1.0]
    np.testing.assert_allclose(prefilter(moved, 300, 0.7).vertices, expected, atol=1e-6)


def test_a_flat_sheet_stays_in_its_plane():
    tm = trimesh.creation.box().subdivide().subdivide().subdivide()
    top = tm.vertices[:, 2] > 0.49
    faces = tm.faces[top[tm.faces].all(axis=1)]
    used = np.unique(faces)
    remap = np.full(len(tm.vertices), -1)
    remap[used] = np.arange(len(used))
    sheet = Mesh(np.asarray(tm.vertices[used], np.float64), remap[faces])
    out = prefilter(sheet, 10, 0.5)
    np.testing.assert_allclose(out.vertices[:, 2], sheet.vertices[:, 2], atol=1e-9)


@pytest.mark.parametrize("target, length", [(20_000, 0.5), (1000, 0.0)])
def test_nothing_to_filter_returns_the_mesh(target, length):
    sphere = _sphere(4)  # 2,562 vertices
    assert prefilter(sphere, target, length) is sphere


def test_a_vertex_without_a_face_of_area_keeps_its_place():
    sphere = _sphere(4)
    vertices = np.vstack([sphere.vertices, [[9.0, 9.0, 9.0]]])  # unreferenced
    out = prefilter(Mesh(vertices, sphere.faces), 100, 0.5)
    np.testing.assert_array_equal(out.vertices[-1], [9.0, 9.0, 9.0])
    assert np.isfinite(out.vertices).all()


def test_the_describe_filters_only_meshes_it_decimates():
    from app.core.pipeline import DescribeParams, canonical_mesh

    # the full strength at every ratio (the default ramp is tested below)
    on = DescribeParams(antialias=0.5, antialias_start=1.0, antialias_full=1.0)
    off = DescribeParams(antialias=0.0)
    # 242 vertices, about a SHREC'11 mesh: subdivided once into the band, never filtered
    coarse = trimesh.creation.uv_sphere(count=[12, 12])
    coarse = Mesh(np.asarray(coarse.vertices, np.float64), np.asarray(coarse.faces, np.int64))
    assert coarse.n_vertices == 242 and 667 <= canonical_mesh(coarse, on).n_vertices <= 1500
    np.testing.assert_array_equal(canonical_mesh(coarse, on).vertices, canonical_mesh(coarse, off).vertices)
    rng = np.random.default_rng(1)
    fine = _sphere(5)  # 10,242 vertices: decimated
    noisy = Mesh(fine.vertices + rng.normal(0, 0.004, fine.vertices.shape), fine.faces)

    def radial_spread(mesh: Mesh) -> float:
        return float(np.linalg.norm(mesh.vertices, axis=1).std())

    # the noise that survives decimation into the canonical mesh is what the filter removed first
    assert radial_spread(canonical_mesh(noisy, on)) < 0.6 * radial_spread(canonical_mesh(noisy, off))


@pytest.mark.parametrize("ratio, expected", [(1.5, 0.0), (4.0, 0.0), (6.0, 0.125), (10.0, 0.375), (12.0, 0.5),
                                             (40.0, 0.5)])
def test_the_length_ramps_linearly_with_the_decimation_ratio(ratio, expected):
    assert ramp_length(0.5, ratio, (4.0, 12.0)) == pytest.approx(expected)


def test_an_empty_ramp_is_a_step():
    assert ramp_length(0.5, 7.9, (8.0, 8.0)) == 0.0
    assert ramp_length(0.5, 8.0, (8.0, 8.0)) == 0.5


def test_simplify_ramps_the_low_pass_by_the_inputs_ratio(monkeypatch):
    from app.core import resolution

    lengths = []

    def spy(mesh, target_vertices, length):
        lengths.append(length)
        return mesh

    monkeypatch.setattr(resolution, "prefilter", spy)
    sphere = _sphere(5)  # 10,242 vertices to 1,000: ratio 10.242, 0.78 of the way from 4 to 12
    resolution.simplify(sphere, 1000, prefilter_length=0.5, prefilter_ramp=(4.0, 12.0))
    resolution.simplify(sphere, 1000, prefilter_length=0.5, prefilter_ramp=(11.0, 12.0))
    assert lengths == [pytest.approx(0.5 * 6.242 / 8), 0.0]


def test_the_default_ramp_leaves_mild_decimations_alone_and_filters_scans():
    from app.core.pipeline import DescribeParams, canonical_mesh

    on, off = DescribeParams(), DescribeParams(antialias=0.0)
    assert (on.antialias_start, on.antialias_full) == (4.0, 12.0) and on.antialias > 0
    mild = _sphere(4)  # 2,562 vertices: 2.6x, like a re-triangulated SHREC'11 copy or a 3,000-vertex shape
    np.testing.assert_array_equal(canonical_mesh(mild, on).vertices, canonical_mesh(mild, off).vertices)
    scan = _sphere(6)  # 40,962 vertices: 41x, a scan
    rng = np.random.default_rng(2)
    noisy = Mesh(scan.vertices + rng.normal(0, 0.002, scan.vertices.shape), scan.faces)
    spread = {name: float(np.linalg.norm(canonical_mesh(noisy, p).vertices, axis=1).std())
              for name, p in (("on", on), ("off", off))}
    assert spread["on"] < 0.6 * spread["off"]
