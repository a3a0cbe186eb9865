"""app.core.piece_fit: a piece fitted onto the model it was cut from, and onto no other."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from app.config import DescribeSettings
from app.core import piece_fit, piece_rank
from app.core.mesh import Mesh
from app.core.partial_match import CAP, PartialMatch, match_many
from app.core.pipeline import LOCAL, describe
from app.core.resolution import to_resolution
from tests.api.test_partial_api import _shapes

PARAMS = DescribeSettings(k=300, m=20, target_vertices=1000).params()


def _describe(mesh: trimesh.Trimesh):
    return describe(Mesh(np.asarray(mesh.vertices, float), np.asarray(mesh.faces)), PARAMS).local


def _moved(mesh: trimesh.Trimesh, rotation: np.ndarray, scale: float, mirror: bool) -> trimesh.Trimesh:
    """The mesh under x -> scale R M x + t (M mirrors x when `mirror`), its faces rewound if mirrored."""
    m = np.diag([-1.0, 1.0, 1.0]) if mirror else np.eye(3)
    vertices = scale * np.asarray(mesh.vertices) @ (rotation @ m).T + np.array([3.0, -1.0, 7.0])
    faces = np.asarray(mesh.faces)[:, ::-1] if mirror else np.asarray(mesh.faces)
    return trimesh.Trimesh(vertices, faces, process=False)


def _canonical(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh at the canonical resolution: described again, it keeps its vertices."""
    out = to_resolution(Mesh(np.asarray(mesh.vertices, float), np.asarray(mesh.faces)), 1000)
    return trimesh.Trimesh(out.vertices, out.faces, process=False)


def _piece(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """About three quarters of the mesh: the faces on one side of an oblique plane. It keeps enough of
    the canonical mesh's vertices to be described on them (a piece of a stored model, as cut)."""
    normal = np.array([0.8, 0.5, 0.33]) / np.linalg.norm([0.8, 0.5, 0.33])
    height = (mesh.triangles_center - mesh.centroid) @ normal
    keep = height > np.quantile(height, 0.25)
    return trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=True)


@pytest.fixture(scope="module")
def bodies() -> dict:
    """The five bodies (at the canonical resolution) and the torus, each as a local signature, and a
    piece of the quadruped."""
    shapes = {n: _canonical(m) if n != "torus" else m for n, m in _shapes().items()}
    return {"shapes": {n: _describe(m) for n, m in shapes.items()}, "half": _piece(shapes["quadruped"]),
            "whole": shapes["quadruped"]}


def _fit(query, model) -> piece_fit.PieceFit | None:
    (match,) = match_many(query, [model], LOCAL)
    (screen,) = piece_fit.screens(query, [model], [match], LOCAL)
    return None if screen is None else piece_fit.fit(query, model, screen)


@pytest.mark.parametrize("scale,mirror",
                         [(1.0, False), (25.4, False), (0.001, False), (1.0, True), (0.04, True)])
def test_a_piece_moved_rescaled_or_mirrored_lies_on_the_model_it_was_cut_from(bodies, random_rotation,
                                                                                scale, mirror):
    half = bodies["half"]
    piece = _describe(_moved(half, random_rotation(7), scale, mirror))
    got = _fit(piece, bodies["shapes"]["quadruped"])
    assert got is not None and got.lies_on, got
    # each surface at unit area: scale² is the share of the whole's area the piece is
    assert got.share == pytest.approx(half.area / bodies["whole"].area, abs=0.12)
    assert got.similarity.mirrored == mirror
    assert got.residual < 1.0  # in vertex spacings: the piece's samples sit on the whole's surface


def test_a_piece_lies_on_no_other_shape(bodies):
    piece = _describe(bodies["half"])
    for name, model in bodies["shapes"].items():
        got = _fit(piece, model)
        assert (got is not None and got.lies_on) == (name == "quadruped"), (name, got)


def test_no_surface_no_fit(bodies):
    piece, model = _describe(bodies["half"]), bodies["shapes"]["quadruped"]
    (match,) = match_many(piece, [model], LOCAL)
    assert piece_fit.screens(piece, [replace(model, surface=None)], [match], LOCAL) == [None]
    assert piece_fit.screens(replace(piece, surface=None), [model], [match], LOCAL) == [None]


def test_a_fit_that_shrinks_the_piece_onto_a_corner_shows_nothing():
    """A piece standing for a share of the model outside SHARE never lies on it, however covered."""
    def at(scale: float, covered: float = 1.0) -> piece_fit.PieceFit:
        return piece_fit.PieceFit(covered=covered, residual=0.0,
                                  similarity=piece_fit.Similarity(scale, np.eye(3), np.zeros(3)))

    small, large = at(0.3), at(1.2)
    fits = [small, at(0.8, 0.9), large, at(0.9, 0.79), None, at(0.7, 0.95)]
    assert not small.lies_on and not large.lies_on
    assert piece_fit.leading(fits) == [5, 1]  # those that lie on their model, the most covered first


def test_the_check_puts_the_piece_on_its_model_and_on_no_other(bodies, random_rotation):
    """Two ICP rounds of 64 of the piece's samples from the screen's starts: on the model it was cut
    from (moved, rescaled, mirrored) most of them lie on its surface, and that model is the most
    promising of the bodies; on the others far fewer do."""
    piece = _describe(_moved(bodies["half"], random_rotation(3), 0.04, True))
    names = list(bodies["shapes"])
    models = [bodies["shapes"][n] for n in names]
    got = dict(zip(names, piece_fit.screens(piece, models, match_many(piece, models, LOCAL), LOCAL),
                   strict=True))
    own = got.pop("quadruped")
    assert own is not None and own.checked >= 0.8, own
    others = [s for s in got.values() if s is not None]
    assert others and max(s.checked for s in others) < own.checked - 0.2, got
    assert all(s.promise < own.promise for s in others)


def test_a_check_with_no_start_is_zero():
    assert piece_fit._check(np.zeros((5, 3)), np.eye(3), ()) == 0.0


def test_the_candidates_fitted_are_those_of_most_promise_and_the_first_by_score(monkeypatch):
    monkeypatch.setattr(piece_fit, "BY_SCREEN", 2)
    monkeypatch.setattr(piece_fit, "BY_SCORE", 2)
    start = (piece_fit.Similarity(1.0, np.eye(3), np.zeros(3)),)
    # promise: the check and half the inliers; 0.5, 0.45, 0.6, 0.3
    screened = [piece_fit.Screen(i, start, c) for i, c in ((0.2, 0.4), (0.9, 0.0), (0.4, 0.4), (0.2, 0.2))]
    screened += [None, piece_fit.Screen(0.8, (), 1.0)]
    # by score: 5 (no start: never fitted), 4 (no screen), 3, 1, 0, 2
    assert piece_fit.to_fit(screened, [5, 4, 3, 1, 0, 2]) == [2, 0, 3, 1]


def test_past_the_deadline_the_fits_stop_after_the_first_and_say_so(bodies, monkeypatch):
    """The screens stop at the first chunk past the deadline, the fits after the `always` first; the
    Fitted says how far it got. With no deadline every candidate is screened and every chosen one
    fitted."""
    piece = _describe(bodies["half"])
    models = list(bodies["shapes"].values())
    found = match_many(piece, models, LOCAL)
    whole = piece_fit.fitted(piece, models, found, LOCAL)
    assert (whole.screened, whole.screen_of) == (len(models), len(models)) and not whole.cut
    assert whole.made == whole.chosen == sum(f is not None for f in whole.fits) >= 1
    assert whole.again == 0  # it lies on the quadruped: no second look
    monkeypatch.setattr(piece_fit, "CHUNK", 2)
    late = piece_fit.fitted(piece, models, found, LOCAL, deadline=time.monotonic() - 1.0, always=1)
    assert (late.screened, late.screen_of) == (2, len(models)) and late.cut
    assert late.made == 1 == sum(f is not None for f in late.fits)


def test_a_piece_that_lies_on_nothing_gets_a_second_look(bodies, monkeypatch):
    """When no first fit passes, the most promising candidates are screened again with other triples
    and fitted again; a second fit that passes takes the first's place."""
    piece = _describe(bodies["half"])
    names = list(bodies["shapes"])
    models = [bodies["shapes"][n] for n in names]
    found = match_many(piece, models, LOCAL)
    seeds: list[int] = []
    real_screens, real_fit = piece_fit.screens, piece_fit.fit

    def screens(*args, seed=0):
        seeds.append(seed)
        return real_screens(*args, seed=seed)

    def fit(query, model, screen):  # every first fit fails: its starts were wrong
        got = real_fit(query, model, screen)
        second = seeds[-1] >= piece_fit.SECOND_SEED
        return got if second or got is None else replace(got, covered=0.0)

    monkeypatch.setattr(piece_fit, "screens", screens)
    monkeypatch.setattr(piece_fit, "fit", fit)
    done = piece_fit.fitted(piece, models, found, LOCAL)
    assert 1 <= done.again <= min(done.made, piece_fit.SECOND)
    assert [s for s in seeds if s >= piece_fit.SECOND_SEED], seeds  # other draws than the first
    lying = [names[j] for j in piece_fit.leading(done.fits)]
    assert lying[:1] == ["quadruped"], lying


def _own(own: float) -> PartialMatch:
    return PartialMatch(distance=own, forward=0.5, reverse=0.5, scale=1.0)


def test_the_candidates_a_piece_lies_on_lead_and_anchor_the_order_from_the_next_hit():
    found = [_own(0.1 * CAP), _own(0.2 * CAP), _own(0.9 * CAP), _own(0.3 * CAP), _own(0.25 * CAP), None]
    vectors = np.array([[0.0], [0.1], [5.0], [5.1], [0.2], [0.0]])
    # no fit: by score; the first page is all of them here
    assert piece_rank.by_score(found, vectors) == [0, 1, 4, 3, 2, 5]
    # the piece lies on candidate 2: it leads, and from the next hit on its neighbours in the global space
    # (3 before 1, 4 and 0) come first, whatever the page
    assert piece_rank.by_score(found, vectors, lead=[2]) == [2, 3, 0, 1, 4, 5]
    # an unscored candidate never leads
    assert piece_rank.by_score(found, vectors, lead=[5, 2]) == [2, 3, 0, 1, 4, 5]


def test_a_stored_copy_of_the_query_leads_but_the_first_real_fit_anchors():
    """A copy of the query (distance about 0) lies on itself and leads; the model the piece was cut
    from is the anchor of the rest, as a copy's own global vector is the piece's."""
    from app.core.partial_match import COPY_DISTANCE

    found = [_own(0.1 * CAP), _own(0.2 * CAP), _own(0.9 * CAP), _own(0.3 * CAP), _own(0.25 * CAP),
             _own(COPY_DISTANCE / 2)]
    vectors = np.array([[0.0], [0.1], [5.0], [5.1], [0.2], [9.0]])
    assert piece_rank.by_score(found, vectors, lead=[5, 2]) == [5, 2, 3, 0, 1, 4]
    # only the copy lies on a fit: the order is the one without fits (the copy first by its score, the
    # first page by score, the best-scored real candidate the anchor past it)
    assert piece_rank.by_score(found, vectors, lead=[5]) == piece_rank.by_score(found, vectors)
    assert piece_rank.by_score(found, vectors, lead=[5], page=1) == [5, 0, 1, 4, 3, 2]


def test_triples_of_right_pairs_come_first_however_few_they_are(random_rotation):
    """Pairs of which 1 in 4 is right (src -> its image under a similarity, the rest sent anywhere):
    of 128 triples drawn at random about 2 would be all right; the triangle test puts the triples
    of right pairs first, and every triple it takes as agreeing is one of them, as a rotation and as
    a reflection."""
    rng = np.random.default_rng(3)
    src = rng.uniform(-0.5, 0.5, size=(200, 3))
    right = np.zeros(len(src), bool)
    right[::4] = True
    dst = 0.8 * src @ random_rotation(5).T + np.array([0.1, 0.2, -0.3])
    dst[~right] = rng.uniform(-0.5, 0.5, size=(int((~right).sum()), 3))
    tolerance = 0.01
    pick = piece_fit._triples(src, dst, np.random.default_rng(0), tolerance)
    half = piece_fit.HYPOTHESES // 2
    assert pick.shape == (piece_fit.HYPOTHESES, 3)
    assert np.array_equal(pick[:half], pick[half:])  # each triple as a rotation and as a reflection
    all_right = right[pick[:half]].all(axis=1)
    # of the 2048 drawn, ~32 are all right (a few are left behind: a side under 2 tolerances), and a
    # wrong triple agrees by chance about once in 1,000
    assert all_right[:24].sum() >= 20
    # the leading triples of right pairs keep their sides' ratios: the similarity's scale
    first = pick[:24][all_right[:24]]
    q, m = src[first], dst[first]
    def sides(t: np.ndarray) -> np.ndarray:
        return np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2)

    assert np.allclose(sides(m) / sides(q), 0.8)
