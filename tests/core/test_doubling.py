"""app.core.doubling: the double of an open surface, and what its spectrum is."""

from __future__ import annotations

import numpy as np
import trimesh

from app.core.doubling import DOUBLE_RIM, doubled
from app.core.laplacian import laplacian
from app.core.partial import free_boundary
from app.core.spectrum import smallest_eigenpairs


def _square(cells: int) -> tuple[np.ndarray, np.ndarray]:
    """The unit square, cells x cells squares each split in two: vertices (n, 3), faces (f, 3)."""
    x, y = np.meshgrid(np.linspace(0, 1, cells + 1), np.linspace(0, 1, cells + 1))
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    i = np.arange(cells)[:, None] * (cells + 1) + np.arange(cells)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + 1, i.ravel() + cells + 1, i.ravel() + cells + 2
    return vertices, np.vstack([np.column_stack([a, b, d]), np.column_stack([a, d, c])])


def test_the_double_shares_the_rim_and_copies_the_rest_flipped():
    vertices, faces = _square(4)
    v2, f2 = doubled(vertices, faces)
    rim = free_boundary(faces, len(vertices))
    assert len(v2) == len(vertices) + int((~rim).sum()) and len(f2) == 2 * len(faces)
    assert np.array_equal(v2[: len(vertices)], vertices) and np.array_equal(f2[: len(faces)], faces)
    assert not free_boundary(f2, len(v2)).any()  # closed: every edge has two faces
    # the copy's faces are the originals reversed, on the same positions
    assert np.allclose(v2[f2[len(faces):]], vertices[faces][:, ::-1])
    # an interior edge between two rim vertices (at the corners) is in both sheets, on the same pair:
    # every vertex pair is used by an even number of faces, and with the edges counted so (3f / 2),
    # V - E + F is a sphere's: the square's pillow
    _, uses = np.unique(np.sort(f2[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0, return_counts=True)
    assert np.all(uses % 2 == 0) and set(uses.tolist()) == {2, 4}
    assert len(v2) - 3 * len(f2) // 2 + len(f2) == 2
    assert trimesh.Trimesh(v2, f2, process=False).is_winding_consistent


def test_the_doubled_squares_spectrum_is_its_neumann_and_dirichlet_spectra():
    """The double of a domain carries the even (Neumann) and odd (Dirichlet) modes: for the unit square
    pi^2 (m^2 + n^2) with m, n >= 0, and with m, n >= 1."""
    vertices, faces = _square(40)
    stiffness, mass = laplacian(*doubled(vertices, faces), "cotangent")
    got = smallest_eigenpairs(stiffness, mass, 12).eigenvalues
    neumann = [m * m + n * n for m in range(5) for n in range(5)]
    dirichlet = [m * m + n * n for m in range(1, 5) for n in range(1, 5)]
    want = np.pi**2 * np.sort(neumann + dirichlet)[:12].astype(float)
    assert abs(got[0]) < 1e-8
    assert np.allclose(got[1:], want[1:], rtol=0.02)


def test_a_closed_surface_doubles_into_two_copies():
    sphere = trimesh.creation.icosphere(2)
    v2, f2 = doubled(np.asarray(sphere.vertices), np.asarray(sphere.faces))
    assert len(v2) == 2 * len(sphere.vertices)
    stiffness, mass = laplacian(v2, f2, "cotangent")
    values = smallest_eigenpairs(stiffness, mass, 4).eigenvalues
    assert np.allclose(values[:2], 0.0, atol=1e-8) and values[2] > 1.0  # two components


def _front(mesh: trimesh.Trimesh, toward: np.ndarray) -> trimesh.Trimesh:
    """The faces that face a viewer far along `toward`: a one-sided view's surface (the front of every
    limb at once, its rim along each silhouette)."""
    keep = mesh.face_normals @ toward > 0
    return trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=True)


def test_a_view_of_a_body_is_described_on_its_double_and_reads_closer_to_its_whole(monkeypatch):
    from app.core import pipeline
    from app.core.meshdata import Mesh
    from app.datasets.synthetic import make_shape

    whole = trimesh.Trimesh(*make_shape("quadruped", np.random.default_rng(0)), process=True)
    front = _front(whole, np.array([0.3, -1.0, 0.4]) / np.linalg.norm([0.3, -1.0, 0.4]))
    to_mesh = lambda m: Mesh(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64))  # noqa: E731
    params = pipeline.DescribeParams()
    seen = pipeline.describe(to_mesh(front), params)
    assert seen.local is not None and seen.local.rim > DOUBLE_RIM
    assert np.all(seen.local.valid == seen.local.slopes.shape[1])  # the double has no rim to distrust
    monkeypatch.setattr(pipeline, "DOUBLE_RIM", np.inf)  # the same view solved as it is
    plain = pipeline.describe(to_mesh(front), params)
    assert plain.local is not None and np.any(plain.local.valid < plain.local.slopes.shape[1])
    reference = pipeline.describe(to_mesh(whole), params)

    def dna(d: pipeline.ShapeDescription) -> np.ndarray:  # the scale-free spectrum's first 30 ratios
        return d.eigenvalues[1:31] / d.eigenvalues[1]

    gap = lambda d: float(np.abs(np.log(dna(d) / dna(reference))).mean())  # noqa: E731
    assert gap(seen) < 0.5 * gap(plain)


def test_a_strip_that_is_all_rim_reads_its_rim_and_is_doubled():
    """Every vertex of a two-row strip is on its free boundary, and none has a neighbour off it: a
    surface that is all rim has loops and no caps (app.core.partial.rim_length), so the rim reads the
    strip's perimeter over √area, past DOUBLE_RIM."""
    from app.core.partial import rim_length

    n = 40
    vertices = np.array([[x, y, 0.0] for x in range(n) for y in (0.0, 1.0)])
    faces = np.array([[2 * i, 2 * i + 2, 2 * i + 3] for i in range(n - 1)]
                     + [[2 * i, 2 * i + 3, 2 * i + 1] for i in range(n - 1)])
    rim = free_boundary(faces, len(vertices))
    assert rim.all()
    assert np.isclose(rim_length(vertices, faces, rim), (2 * (n - 1) + 2) / np.sqrt(n - 1))
    assert rim_length(vertices, faces, rim) > DOUBLE_RIM
