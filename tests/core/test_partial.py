"""Local signatures and partial matching (app.core.partial, app.core.partial_match): the mathematics."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from app.core.holes import fill_holes
from app.core.laplacian import laplacian
from app.core.mesh import Mesh
from app.core.partial import (
    LocalParams,
    LocalSignature,
    farthest_points,
    free_boundary,
    local_signature,
    log_heat,
    log_slopes,
    rim_distance,
    rim_length,
)
from app.core.partial_match import (
    CAP,
    LEVEL,
    MIN_SLOPES,
    MUTUAL,
    VOTE,
    PartialMatch,
    head,
    level_at,
    match_many,
    mutual_shares,
    region,
    regions,
    trusted_area,
    votes,
)
from app.core.resolution import normalize_scale
from app.core.spectrum import Spectrum, smallest_eigenpairs

PARAMS = LocalParams(points=64)


def unit_mesh(mesh: trimesh.Trimesh) -> Mesh:
    return normalize_scale(Mesh(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)))


def spectrum_of(mesh: Mesh, k: int = 120) -> tuple[Spectrum, np.ndarray]:
    stiffness, mass = laplacian(mesh.vertices, mesh.faces, "cotangent")
    return smallest_eigenpairs(stiffness, mass, k), mass.diagonal()


@pytest.fixture(scope="module")
def sphere() -> tuple[Mesh, Spectrum, np.ndarray]:
    mesh = unit_mesh(trimesh.creation.icosphere(3))  # 642 vertices
    spectrum, mass = spectrum_of(mesh)
    return mesh, spectrum, mass


def test_slopes_of_a_scaled_surface_are_the_same_slopes_later():
    """Scaling a surface by s gives λ/s² and φ/s: its slopes at times s²t are the slopes at t, exactly.
    This is what turns the scale of a piece into a shift of the grid."""
    rng = np.random.default_rng(0)
    lam = np.sort(rng.uniform(0, 500, 40))
    lam[0] = 0.0
    phi = rng.normal(size=(30, 40))
    times = PARAMS.times()
    s = 1.7
    scaled = log_slopes(Spectrum(lam / s**2, phi / s), times * s**2)
    assert np.allclose(scaled, log_slopes(Spectrum(lam, phi), times), atol=1e-10)


def test_a_scaled_surfaces_level_at_its_shift_is_the_level():
    """log(t·K_t(x, x)) is scale free: a surface scaled by s (s² = ratio^shift, the kept share 1/s²)
    read `shift` grid steps later has the level the whole has at the grid's start. level_at rebuilds it
    from the query's level at t0 and its slopes, as match_many reads a scale hypothesis."""
    rng = np.random.default_rng(1)
    lam = np.sort(rng.uniform(0, 500, 40))
    lam[0] = 0.0
    phi = rng.normal(size=(30, 40))
    shift = 3
    s = np.sqrt(PARAMS.ratio ** shift)
    times = PARAMS.times(PARAMS.shifts - 1)

    def signature(spectrum: Spectrum) -> LocalSignature:
        logk = log_heat(spectrum, times)
        return LocalSignature(slopes=log_slopes(spectrum, times, logk), area=np.full(30, 1 / 30),
                              valid=np.full(30, len(times) - 1, np.int16), rim=0.0,
                              level=logk[:, 0] + np.log(times[0]))

    whole, scaled = signature(Spectrum(lam, phi)), signature(Spectrum(lam / s**2, phi / s))
    assert whole.level is not None
    assert np.allclose(level_at(scaled, shift, PARAMS), whole.level, atol=1e-9)
    assert np.allclose(level_at(whole, 0, PARAMS), whole.level)
    # and not at another shift: the level rises by (slope + 1)·log(ratio) a step
    assert not np.allclose(level_at(scaled, shift - 1, PARAMS), whole.level, atol=1e-3)


def test_the_level_ranks_but_the_forward_share_reads_the_slopes():
    """By hand: two models with the query's slopes, one at its level, one a level of 0.3 higher. The
    second is further by LEVEL·0.3² (under the cap) and ranks second; both cover the
    whole query (forward 1: the tolerance reads the slopes alone). A model described before levels
    were stored is compared on its slopes alone."""
    width = PARAMS.slopes + PARAMS.shifts - 1
    # flat (slope -1: K ~ 1/4πt), so the level does not change with the scale hypothesis either
    slopes = np.full((2, width), -1.0, np.float32)
    valid = np.array([width, width], np.int16)
    area = np.array([0.5, 0.5], np.float32)
    query = LocalSignature(slopes=slopes, area=area, valid=valid, rim=1.0,
                           level=np.array([0.2, 0.2], np.float32))
    same = LocalSignature(slopes=slopes[:, :PARAMS.slopes], area=area, valid=valid, rim=0.0,
                          level=np.array([0.2, 0.2], np.float32))
    higher = replace(same, level=same.level + 0.3)
    unknown = replace(same, level=None)
    at, above, bare = match_many(query, [same, higher, unknown], PARAMS)
    assert LEVEL * 0.09 < CAP
    assert at.distance == pytest.approx(0.0, abs=1e-12) and at.shift == 0
    assert above.distance == pytest.approx(LEVEL * 0.09, rel=1e-5)
    assert bare.distance == pytest.approx(0.0, abs=1e-12)
    assert at.forward == above.forward == bare.forward == pytest.approx(1.0)


def test_slopes_on_a_sphere_go_from_flat_to_filled(sphere):
    """A unit-area sphere (R² = 1/4π): at short times K ≈ (1 + t/3R²)/(4πt), a slope of
    -1 + 4πt/3 (-0.96 at t = 0.01); once heat has filled the sphere K tends to 1/area (slope 0)."""
    _, spectrum, _ = sphere
    slopes = log_slopes(spectrum, np.array([1e-2, 1.1e-2, 5.0, 5.5]))
    assert np.allclose(slopes[:, 0], -1 + 4 * np.pi * 0.0105 / 3, atol=0.03)
    assert np.allclose(slopes[:, 2], 0.0, atol=1e-3)


def test_free_boundary_and_rim_length_by_hand():
    # the unit square cut in four triangles around its centre: the rim is its 4 sides
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0]], float)
    f = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    rim = free_boundary(f, 5)
    assert rim.tolist() == [True, True, True, True, False]
    assert rim_length(v, f, rim) == pytest.approx(4.0)
    # scaled by 3: the length over √area does not change
    assert rim_length(3 * v, f, rim) == pytest.approx(4.0)


def test_a_hole_closed_by_a_cap_keeps_its_rim_length():
    """The cap's centre is flagged as rim with the loop; its spokes are not rim edges."""
    ball = trimesh.creation.icosphere(3)
    keep = ball.triangles_center[:, 2] > -0.6  # a sphere with a small hole at the south pole
    mesh = Mesh(ball.vertices, ball.faces[keep])
    used = np.unique(mesh.faces)
    remap = np.full(len(mesh.vertices), -1)
    remap[used] = np.arange(len(used))
    mesh = Mesh(mesh.vertices[used], remap[mesh.faces])
    rim = free_boundary(mesh.faces, mesh.n_vertices)
    closed, count = fill_holes(mesh, 0.5)
    assert count == 1
    capped_rim = np.concatenate([rim, [True]])
    assert rim_length(closed.vertices, closed.faces, capped_rim) == pytest.approx(
        rim_length(mesh.vertices, mesh.faces, rim) * np.sqrt(mesh.area() / closed.area()))


def test_an_edge_between_two_holes_is_not_rim():
    """Two one-face holes joined by an edge that two faces still share: the rim is the two holes'
    perimeters, not that edge too (the version before counted every edge between two rim vertices)."""
    ball = trimesh.creation.icosphere(2)
    v, f = np.asarray(ball.vertices), np.asarray(ball.faces)
    a, b = ball.edges_unique[0]  # the edge that will join the two holes

    def around(x: int, y: int) -> list[int]:  # the faces at x that do not hold y
        return [int(i) for i in np.flatnonzero((f == x).any(axis=1)) if y not in f[i]]

    first, joined = next((i, j) for i in around(a, b) for j in around(b, a) if not set(f[i]) & set(f[j]))
    holed = np.delete(f, [first, joined], axis=0)
    rim = free_boundary(holed, len(v))
    assert rim.sum() == 6

    def perimeter(face: np.ndarray) -> float:
        return float(sum(np.linalg.norm(v[face[i]] - v[face[(i + 1) % 3]]) for i in range(3)))

    area = Mesh(v, holed).area()
    expected = (perimeter(f[first]) + perimeter(f[joined])) / np.sqrt(area)
    assert rim_length(v, holed, rim) == pytest.approx(expected)


def test_a_closed_surface_has_no_rim(sphere):
    mesh, _, _ = sphere
    rim = free_boundary(mesh.faces, mesh.n_vertices)
    assert not rim.any() and rim_length(mesh.vertices, mesh.faces, rim) == 0.0
    assert np.isinf(rim_distance(mesh.vertices, rim)).all()


def test_farthest_points_spread_and_never_repeat(sphere):
    mesh, _, _ = sphere
    chosen = farthest_points(mesh.vertices, 50)
    assert chosen[0] == 0 and len(set(chosen.tolist())) == 50
    gaps = np.linalg.norm(mesh.vertices[chosen][:, None] - mesh.vertices[chosen][None], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    # 50 points on a unit-area sphere: none closer than half the spacing of an even cover
    assert gaps.min() > 0.5 * np.sqrt(1.0 / 50)
    assert len(farthest_points(mesh.vertices[:10], 50)) == 10


def test_signature_areas_sum_to_one_and_a_rim_distrusts_its_neighbourhood():
    half = trimesh.creation.icosphere(3)
    keep = half.triangles_center[:, 2] > 0.0
    mesh = unit_mesh(trimesh.Trimesh(half.vertices, half.faces[keep], process=True))
    spectrum, mass = spectrum_of(mesh)
    rim = free_boundary(mesh.faces, mesh.n_vertices)
    sig = local_signature(spectrum, mesh.vertices, mesh.faces, mass, rim, PARAMS)
    width = PARAMS.slopes + PARAMS.shifts - 1
    assert sig.slopes.shape == (64, width) and sig.slopes.dtype == np.float32
    assert sig.area.sum() == pytest.approx(1.0, abs=1e-5)
    # a hemisphere's rim: 2π r over √(2π r²) = √(2π); cut along the triangles, it zigzags a little
    assert np.sqrt(2 * np.pi) < sig.rim < 1.2 * np.sqrt(2 * np.pi)
    near = rim_distance(mesh.vertices, rim)[farthest_points(mesh.vertices, 64)]
    assert (sig.valid[near == 0] == 0).all()  # a sample on the rim trusts nothing
    assert (np.diff(sig.valid[np.argsort(near)]) >= 0).all()  # farther from the rim, more trusted


def test_a_model_matches_itself_fully(sphere):
    mesh, spectrum, mass = sphere
    rim = np.zeros(mesh.n_vertices, bool)
    sig = local_signature(spectrum, mesh.vertices, mesh.faces, mass, rim, PARAMS)
    (m,) = match_many(sig, [sig], PARAMS)
    assert m.distance == pytest.approx(0.0, abs=1e-9)
    assert m.forward == 1.0 and m.reverse == pytest.approx(1.0) and m.scale == pytest.approx(1.0)


@pytest.mark.parametrize("shift", [1, 2, 3])
def test_a_query_smaller_by_a_grid_step_is_found_at_that_scale(sphere, shift):
    """A query that is the model's surface with a kept share f = ratio^-shift, normalised to unit area
    (λ·f, φ·√f), matches at that shift with no loss and reports reverse = f."""
    mesh, spectrum, mass = sphere
    rim = np.zeros(mesh.n_vertices, bool)
    model = local_signature(spectrum, mesh.vertices, mesh.faces, mass, rim, PARAMS)
    f = PARAMS.ratio ** -shift
    piece = Spectrum(spectrum.eigenvalues * f, spectrum.eigenvectors * np.sqrt(f))
    # the same vertices: a scaled copy can pick other samples among the sphere's exact ties
    query = local_signature(piece, mesh.vertices, mesh.faces, mass / f, rim, PARAMS)
    (m,) = match_many(query, [model], PARAMS)
    assert m.distance == pytest.approx(0.0, abs=1e-9)
    assert m.scale == pytest.approx(f, rel=0.02)
    assert m.forward == 1.0 and m.reverse == pytest.approx(f, rel=0.02)


def test_another_shape_matches_less_than_the_same_one(sphere):
    mesh, spectrum, mass = sphere
    none = np.zeros(mesh.n_vertices, bool)
    ball = local_signature(spectrum, mesh.vertices, mesh.faces, mass, none, PARAMS)
    cigar = unit_mesh(trimesh.creation.capsule(height=4.0, radius=0.4, count=[24, 24]))
    c_spec, c_mass = spectrum_of(cigar)
    tube = local_signature(c_spec, cigar.vertices, cigar.faces, c_mass, np.zeros(cigar.n_vertices, bool),
                           PARAMS)
    same, other = match_many(ball, [ball, tube], PARAMS)
    assert same.distance < other.distance and same.forward > other.forward


def test_models_without_trusted_samples_score_nothing_and_grids_are_checked(sphere):
    mesh, spectrum, mass = sphere
    sig = local_signature(spectrum, mesh.vertices, mesh.faces, mass, np.zeros(mesh.n_vertices, bool), PARAMS)
    rimmed = LocalSignature(sig.slopes, sig.area, np.zeros_like(sig.valid), 1.0)
    got, _ = match_many(sig, [rimmed, sig], PARAMS)
    assert got.forward == 0.0 and got.reverse == 0.0
    assert match_many(sig, [], PARAMS) == []
    short = LocalSignature(sig.slopes[:, :3], sig.area, sig.valid, 0.0)
    with pytest.raises(ValueError, match="shorter"):
        match_many(sig, [short], PARAMS)


def test_an_unmatched_part_of_the_query_costs_its_area_times_the_cap():
    """By hand: a query sample equal to a model sample costs 0 and is found; one far from every model
    sample costs CAP, whatever how far, so a part the model lacks weighs its area and no more."""
    width = PARAMS.slopes + PARAMS.shifts - 1
    model = LocalSignature(slopes=np.array([[0.0] * width, [-1.0] * width], np.float32),
                           area=np.array([0.5, 0.5], np.float32), valid=np.array([width, width], np.int16),
                           rim=0.0)
    for far in (5.0, 50.0):
        query = LocalSignature(slopes=np.array([[0.0] * width, [far] * width], np.float32),
                               area=np.array([0.7, 0.3], np.float32),
                               valid=np.array([width, width], np.int16), rim=1.0)
        (m,) = match_many(query, [model], PARAMS)
        assert m.distance == pytest.approx(0.3 * CAP)
        assert m.forward == pytest.approx(0.7) and m.scale == pytest.approx(1.0)
        assert m.reverse == pytest.approx(0.7)


def test_the_region_is_where_the_query_matched_and_sums_to_forward():
    """By hand: the query's first sample (area 0.7) equals the model's first, its second matches
    nothing; the region puts 0.7 on the model's first sample's vertex and nothing elsewhere."""
    width = PARAMS.slopes + PARAMS.shifts - 1
    model = LocalSignature(slopes=np.array([[0.0] * width, [-1.0] * width, [0.01] * width], np.float32),
                           area=np.full(3, 1 / 3, np.float32), valid=np.array([width, width, 2], np.int16),
                           rim=0.0, vertex=np.array([10, 20, 30], np.int32))
    query = LocalSignature(slopes=np.array([[0.0] * width, [5.0] * width], np.float32),
                           area=np.array([0.7, 0.3], np.float32), valid=np.array([width, width], np.int16),
                           rim=1.0)
    (m,) = match_many(query, [model], PARAMS)
    got = region(query, model, m.shift, PARAMS)
    assert got is not None
    assert got.vertex.tolist() == [10, 20, 30]
    # the third model sample is nearer but sits on the rim (2 trusted slopes): never compared
    assert got.weight == pytest.approx([0.7, 0.0, 0.0])
    assert got.weight.sum() == pytest.approx(m.forward)
    assert region(query, LocalSignature(model.slopes, model.area, model.valid, 0.0), 0, PARAMS) is None


def test_a_pieces_region_sums_to_its_forward_score():
    """A capsule's upper part against the whole: the matched model samples' weights sum to forward
    (the same nearest samples at the winning scale), on the model's own sample vertices. Where the
    region lies is tested on an articulated body through the API (tests/api/test_partial_api.py)."""
    whole = trimesh.creation.capsule(height=3.0, radius=0.5, count=[24, 24])
    keep = whole.triangles_center[:, 2] > -0.4
    piece_t = trimesh.Trimesh(whole.vertices, whole.faces[keep], process=True)
    model_mesh = unit_mesh(whole)
    m_spec, m_mass = spectrum_of(model_mesh)
    model = local_signature(m_spec, model_mesh.vertices, model_mesh.faces, m_mass,
                            np.zeros(model_mesh.n_vertices, bool), PARAMS)
    assert model.vertex is not None
    assert model.vertex.tolist() == farthest_points(model_mesh.vertices, 64).tolist()
    piece = unit_mesh(piece_t)
    p_spec, p_mass = spectrum_of(piece)
    query = local_signature(p_spec, piece.vertices, piece.faces, p_mass,
                            free_boundary(piece.faces, piece.n_vertices), PARAMS)
    (m,) = match_many(query, [model], PARAMS)
    got = region(query, model, m.shift, PARAMS)
    assert got is not None and m.forward > 0.05
    assert got.weight.sum() == pytest.approx(m.forward)
    # under another scale hypothesis the region is another one, and sums to that hypothesis's forward
    other = region(query, model, (m.shift + 3) % PARAMS.shifts, PARAMS)
    assert other is not None and not np.array_equal(other.weight, got.weight)
    # the batched form (a page's hits, grouped by shift into one product) gives each model's region as
    # region() alone does: two models share a product here, one has no vertices, one is on its own
    fewer = head(model, 40)
    bare = LocalSignature(model.slopes, model.area, model.valid, 0.0)
    other = (m.shift + 3) % PARAMS.shifts
    models, shifts = [model, fewer, bare, model], [m.shift, m.shift, m.shift, other]
    batched = regions(query, models, shifts, PARAMS)
    assert batched[2] is None
    for i in (0, 1, 3):
        alone = regions(query, [models[i]], [shifts[i]], PARAMS)[0]
        assert batched[i] is not None and alone is not None
        assert np.array_equal(batched[i].weight, alone.weight)
        assert batched[i].vertex.tolist() == models[i].vertex.tolist()
    coarse = head(model, 8)
    assert coarse.vertex is not None and coarse.vertex.tolist() == model.vertex[:8].tolist()


def test_the_mutual_share_counts_one_to_one_matches_and_weighs_in_the_score_by_MUTUAL():
    """By hand: query samples q0 (area 0.7, equal to model sample m0) and q1 (0.3, far from both). Both
    have m0 as nearest; m0's nearest query sample is q0, m1's is q0 too (1 against 36): only q0's match
    is one to one, so the mutual share is 0.7 and the score 0.3 CAP - MUTUAL x CAP x 0.7."""
    width = PARAMS.slopes + PARAMS.shifts - 1
    model = LocalSignature(slopes=np.array([[0.0] * width, [-1.0] * width], np.float32),
                           area=np.array([0.5, 0.5], np.float32), valid=np.array([width, width], np.int16),
                           rim=0.0)
    query = LocalSignature(slopes=np.array([[0.0] * width, [5.0] * width], np.float32),
                           area=np.array([0.7, 0.3], np.float32), valid=np.array([width, width], np.int16),
                           rim=1.0)
    (plain,) = match_many(query, [model], PARAMS)
    (m,) = match_many(query, [model], PARAMS, mutual=True)
    assert plain.mutual == 0.0 and plain.score == plain.distance  # not asked: the distance alone
    assert m.mutual == pytest.approx(0.7)
    assert m.score == pytest.approx(0.3 * CAP - MUTUAL * CAP * 0.7)
    assert (m.distance, m.forward, m.reverse) == (plain.distance, plain.forward, plain.reverse)
    # a model that also has a look-alike of q1 (m2, nearer to q1 than to q0): both match one to one
    twice = LocalSignature(slopes=np.array([[0.0] * width, [0.0] * width, [4.0] * width], np.float32),
                           area=np.full(3, 1 / 3, np.float32), valid=np.full(3, width, np.int16), rim=0.0)
    assert mutual_shares(query, [twice, model], [0, 0], PARAMS) == pytest.approx([1.0, 0.7])


def test_votes_count_the_query_area_for_which_a_model_is_among_the_nearest():
    """By hand, one scale hypothesis: query samples q0 (area 0.6) and q1 (0.4); model A equals q0 and is
    far from q1, model B is near both but equal to neither, model C equals q1. Per sample the nearest
    models are q0: A, B, C; q1: C, B, A. With top 1, A gets q0's 0.6 and C q1's 0.4; with top 2, B is
    among both samples' two nearest: 1.0, as the look-alike of everything a source need not be."""
    width = PARAMS.slopes + PARAMS.shifts - 1
    q = LocalSignature(slopes=np.array([[0.0] * width, [2.0] * width], np.float32),
                       area=np.array([0.6, 0.4], np.float32), valid=np.full(2, width, np.int16), rim=1.0)

    def model(*rows: float) -> LocalSignature:
        return LocalSignature(slopes=np.array([[r] * width for r in rows], np.float32),
                              area=np.full(len(rows), 1 / len(rows), np.float32),
                              valid=np.full(len(rows), width, np.int16), rim=0.0)

    a, b, c = model(0.0, -3.0), model(0.9, 1.1), model(2.0, 5.0)
    found = match_many(q, [a, b, c], PARAMS)
    assert [m.shift for m in found] == [0, 0, 0]
    assert votes(q, found, PARAMS, top=1) == pytest.approx([0.6, 0.0, 0.4])
    assert votes(q, found, PARAMS, top=2) == pytest.approx([0.6, 1.0, 0.4])
    assert votes(q, found, PARAMS, top=3) == pytest.approx([1.0, 1.0, 1.0])
    voted = replace(found[0], vote=0.6)
    assert voted.score == pytest.approx(found[0].score - VOTE * CAP * 0.6)


def test_a_sample_untrusted_at_a_models_scale_gives_it_no_vote():
    """q1 keeps only MIN_SLOPES slopes: trusted at shift 0, not at shift 1. A model matched at shift 1
    gets no vote from it, and the trusted area is renormalised over the samples trusted there."""
    width = PARAMS.slopes + PARAMS.shifts - 1
    q = LocalSignature(slopes=np.zeros((2, width), np.float32), area=np.array([0.5, 0.5], np.float32),
                       valid=np.array([width, MIN_SLOPES], np.int16), rim=1.0)
    assert trusted_area(q, 0, PARAMS) == pytest.approx([0.5, 0.5])
    assert trusted_area(q, 1, PARAMS) == pytest.approx([1.0, 0.0])
    near = PartialMatch(distance=0.0, forward=1.0, reverse=1.0, scale=1.0, shift=1,
                        nearest=np.array([0.0, np.inf]))
    none = PartialMatch(distance=CAP, forward=0.0, reverse=0.0, scale=1.0)  # no trusted sample: no nearest
    assert votes(q, [near, none], PARAMS, top=1) == pytest.approx([1.0, 0.0])
    assert votes(q, [], PARAMS).shape == (0,)
