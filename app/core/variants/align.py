"""Rigid / similarity alignment of two surfaces: principal-axis hypotheses (mirrored ones included),
refined by ICP, and an exact Procrustes fit on vertex correspondences when the triangulations agree.

A similarity is (scale s, orthogonal R with det +1 or -1, translation t): y = s R x + t.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from app.core.meshdata import Mesh
from app.core.variants.surface import Moments, moments

ICP_ITERATIONS = 20
DEGENERATE_GAP = 0.05  # relative eigenvalue gap below which two principal axes are interchangeable
TRIM = 0.9  # ICP fits the closest 90 % of pairs: holes and extra parts do not drag the fit


@dataclass(frozen=True)
class Frame:
    """Where a surface sits: area centroid (3,), RMS radius, principal axes (3, 3) as columns and their
    eigenvalues (3,)."""

    centroid: np.ndarray
    radius: float
    axes: np.ndarray
    values: np.ndarray

    def normalise(self, x: np.ndarray) -> np.ndarray:
        """(n, 3) world -> (n, 3) centred, unit RMS radius, principal-axis coordinates."""
        return (x - self.centroid) @ self.axes / self.radius


def frame(mesh: Mesh, m: Moments | None = None) -> Frame:
    """The mesh's frame (`m`: its moments when already at hand)."""
    m = m or moments(mesh)
    values, axes = m.axes()
    return Frame(m.centroid, float(np.sqrt(max(values.sum(), 1e-300))), axes, values)


@dataclass(frozen=True)
class Similarity:
    scale: float
    rotation: np.ndarray  # (3, 3), det +1 (proper) or -1 (mirrored)
    translation: np.ndarray  # (3,)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """x (n, 3) -> s x R^T + t, (n, 3)."""
        return self.scale * x @ self.rotation.T + self.translation

    @property
    def mirrored(self) -> bool:
        return bool(np.linalg.det(self.rotation) < 0)

    def matrix(self) -> np.ndarray:
        """(4, 4) homogeneous transform."""
        out = np.eye(4)
        out[:3, :3] = self.scale * self.rotation
        out[:3, 3] = self.translation
        return out


def hypotheses(fa: Frame, fb: Frame) -> list[np.ndarray]:
    """Candidate rotations (3, 3) in normalised coordinates taking A's principal frame onto B's: the 8
    sign choices of the axes (4 proper, 4 mirrored), and turns about any axis pair whose eigenvalues
    are too close to order (a cylinder, a cube) in both meshes."""
    signs = [np.diag(s) for s in np.array(np.meshgrid([1, -1], [1, -1], [1, -1])).T.reshape(-1, 3)]
    values = np.maximum(0.5 * (fa.values + fb.values), 1e-300)
    gaps = (values[:-1] - values[1:]) / values[:-1]  # (2,) between axes 0-1 and 1-2
    extra: list[np.ndarray] = []
    if gaps.min() < DEGENERATE_GAP:
        if gaps.max() < DEGENERATE_GAP:  # no preferred axis at all: the rotations of an icosahedron
            turns = Rotation.create_group("I").as_matrix()
        else:
            axis = np.eye(3)[2 if gaps[0] < DEGENERATE_GAP else 0]  # turn about the distinct axis
            turns = Rotation.from_rotvec(np.outer(np.arange(1, 12) * np.pi / 6, axis)).as_matrix()
        extra = [t @ s for t in turns for s in (signs[0], signs[-1])]
    return signs + extra


def as_they_lie(fa: Frame, fb: Frame) -> np.ndarray:
    """(3, 3) the rotation in normalised coordinates that to_world turns into no turn at all (proper:
    both frames are right-handed). A copy left in place (a hole punched, a decimation, a repair) whose
    principal axes moved, because a part of the surface went, is fitted from where it is."""
    return fb.axes.T @ fa.axes


def icp(
    source: np.ndarray, tree: cKDTree, target: np.ndarray, start: np.ndarray,
    iterations: int = ICP_ITERATIONS, with_scale: bool = False,
) -> tuple[Similarity, float]:
    """Refine x -> start @ x (source (n, 3), target (m, 3) indexed by tree) by trimmed ICP keeping the
    handedness of `start`; returns the similarity and the final mean distance of the kept pairs."""
    start_fit = Similarity(1.0, start, np.zeros(3))
    fits, costs = icp_batch(source, tree, target, [start_fit], iterations, with_scale)
    return fits[0], float(costs[0])


def icp_batch(
    source: np.ndarray, tree: cKDTree, target: np.ndarray, starts: list[Similarity],
    iterations: int = ICP_ITERATIONS, with_scale: bool = False,
) -> tuple[list[Similarity], np.ndarray]:
    """Trimmed ICP from several starting similarities at once (one k-d tree query per round for all
    of them), each keeping its handedness and stopping on its own when it converges.
    source (n, 3), target (m, 3) indexed by tree; returns the fits and their costs (h,): the mean
    distance of the kept pairs in the last round."""
    h, n = len(starts), len(source)
    rot = np.array([s.rotation for s in starts], dtype=float)  # (h, 3, 3)
    scale = np.array([s.scale for s in starts], dtype=float)  # (h,)
    shift = np.array([s.translation for s in starts], dtype=float)  # (h, 3)
    mirrored = det3(rot) < 0
    cost = np.full(h, np.inf)
    active = np.arange(h)
    kth = int(TRIM * (n - 1))
    kept = kth + 1
    for _ in range(iterations):
        if not active.size:
            break
        moved = scale[active, None, None] * source[None] @ rot[active].transpose(0, 2, 1)
        moved += shift[active, None]  # (a, n, 3)
        dist, idx = tree.query(moved.reshape(-1, 3), workers=1)
        dist, idx = dist.reshape(len(active), n), idx.reshape(len(active), n)
        keep = np.argpartition(dist, kth, axis=1)[:, :kept]  # (a, kept) the closest 90 % of pairs
        rows = np.arange(len(active))[:, None]
        # plain indexing and sum / count: take_along_axis and mean, bit for bit, without their overhead
        new_cost = dist[rows, keep].sum(axis=1) / kept
        r, s, t = umeyama_batch(source[keep], target[idx[rows, keep]], mirrored[active], with_scale)
        rot[active], scale[active], shift[active] = r, s, t
        done = cost[active] - new_cost < 1e-4 * new_cost  # converged (coordinates have unit RMS radius)
        cost[active] = np.where(done, np.minimum(cost[active], new_cost), new_cost)
        active = active[~done]
    return [Similarity(float(scale[i]), rot[i], shift[i]) for i in range(h)], cost


def umeyama_batch(
    src: np.ndarray, dst: np.ndarray, mirrored: np.ndarray, with_scale: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """umeyama() for h point sets at once: src, dst (h, n, 3), mirrored (h,) bool -> rotations (h, 3, 3),
    scales (h,), translations (h, 3)."""
    n = src.shape[1]
    mu_s, mu_d = src.sum(axis=1) / n, dst.sum(axis=1) / n  # (h, 3): mean(axis=1), bit for bit
    xs, xd = src - mu_s[:, None], dst - mu_d[:, None]
    u, sig, vt = np.linalg.svd(xd.transpose(0, 2, 1) @ xs)  # (h, 3, 3): a batched matmul, 6x einsum's speed
    d = np.ones((len(src), 3))
    d[(det3(u @ vt) < 0) != mirrored, 2] = -1.0
    rotation = (u * d[:, None, :]) @ vt
    var = (xs**2).sum(axis=(1, 2))
    scale = np.ones(len(src))
    if with_scale:
        scale = np.where(var > 0, (sig * d).sum(axis=1) / np.maximum(var, 1e-300), 1.0)
    return rotation, scale, mu_d - scale[:, None] * np.einsum("hij,hj->hi", rotation, mu_s)


def det3(m: np.ndarray) -> np.ndarray:
    """Determinants (h,) of 3 x 3 matrices m (h, 3, 3) by the rule of Sarrus: only their signs are used,
    on orthogonal matrices (det +-1), and np.linalg.det's per-call overhead is most of its cost here."""
    return (m[:, 0, 0] * (m[:, 1, 1] * m[:, 2, 2] - m[:, 1, 2] * m[:, 2, 1])
            - m[:, 0, 1] * (m[:, 1, 0] * m[:, 2, 2] - m[:, 1, 2] * m[:, 2, 0])
            + m[:, 0, 2] * (m[:, 1, 0] * m[:, 2, 1] - m[:, 1, 1] * m[:, 2, 0]))


def umeyama(src: np.ndarray, dst: np.ndarray, mirrored: bool, with_scale: bool = True) -> Similarity:
    """Least-squares similarity taking src (n, 3) onto dst (n, 3), with det R = -1 if `mirrored`."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    xs, xd = src - mu_s, dst - mu_d
    u, sig, vt = np.linalg.svd(xd.T @ xs)
    d = np.ones(3)
    if (np.linalg.det(u @ vt) < 0) != mirrored:
        d[2] = -1.0
    rotation = u @ np.diag(d) @ vt
    var = float((xs**2).sum())
    scale = float((sig * d).sum() / var) if with_scale and var > 0 else 1.0
    return Similarity(scale, rotation, mu_d - scale * rotation @ mu_s)


def to_world(fa: Frame, fb: Frame, local: Similarity) -> Similarity:
    """A similarity between normalised frames -> the one between the meshes' own coordinates."""
    scale = local.scale * fb.radius / fa.radius
    rotation = fb.axes @ local.rotation @ fa.axes.T
    translation = fb.centroid + fb.radius * fb.axes @ local.translation - scale * rotation @ fa.centroid
    return Similarity(scale, rotation, translation)
