"""Fixtures for the numerical core: small meshes generated in code, never files from the repo."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from app.core.mesh import Mesh


@pytest.fixture(scope="session")
def random_rotation():
    """Factory: seed -> (3, 3) proper rotation."""
    return _random_rotation


def _random_rotation(seed: int) -> np.ndarray:
    """(3, 3) proper rotation from a QR decomposition of a Gaussian matrix."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


@pytest.fixture(scope="session")
def shrec_mesh() -> Mesh:
    """One SHREC'11 mesh (~250 vertices) from SHAPEBAG_DATASETS; skips, saying how to get it, without."""
    from app.core.mesh import load_mesh
    from tests.conftest import dataset_or_skip

    path = dataset_or_skip("shrec11-simplified") / "alien" / "train" / "T133.obj"

    return load_mesh(path)


@pytest.fixture(scope="session")
def ellipsoid_mesh() -> Mesh:
    """A cigar-shaped ellipsoid (642 vertices, long axis z): its HKS has clear maxima at both poles."""
    tm = trimesh.creation.icosphere(subdivisions=3)
    return Mesh(np.asarray(tm.vertices) * [0.6, 0.6, 2.0], np.asarray(tm.faces, np.int64))
