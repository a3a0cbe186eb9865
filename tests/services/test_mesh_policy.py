"""nonmanifold_faces on hand-made cases, and against a brute-force edge count."""

from __future__ import annotations

from collections import Counter

import numpy as np

from app.services.mesh_policy import nonmanifold_faces


def brute_force(faces: np.ndarray) -> np.ndarray:
    edges = [tuple(sorted((int(f[i]), int(f[(i + 1) % 3])))) for f in faces for i in range(3)]
    count = Counter(edges)
    return np.array(
        [any(count[tuple(sorted((int(f[i]), int(f[(i + 1) % 3]))))] > 2 for i in range(3)) for f in faces]
    )


def test_a_closed_tetrahedron_has_no_nonmanifold_face() -> None:
    tet = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]])
    assert not nonmanifold_faces(tet).any()


def test_three_triangles_hinged_on_one_edge_are_all_flagged() -> None:
    fan = np.array([[0, 1, 2], [0, 1, 3], [1, 0, 4], [2, 3, 5]])  # edge (0, 1) shared by three faces
    assert nonmanifold_faces(fan).tolist() == [True, True, True, False]


def test_agrees_with_a_brute_force_count_on_random_faces() -> None:
    rng = np.random.default_rng(3)
    for n in (5, 12, 40):
        faces = np.array([rng.choice(n, 3, replace=False) for _ in range(3 * n)])
        assert np.array_equal(nonmanifold_faces(faces), brute_force(faces))
