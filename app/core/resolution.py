"""Geometric transforms of a clean mesh: scale normalisation, the canonical-resolution policy, noise.

Kept apart from mesh.py (reading, validating, cleaning): these change the geometry on purpose.
"""

from __future__ import annotations

import numpy as np
import trimesh

from app.core.antialias import prefilter, ramp_length
from app.core.cleaning import nonmanifold_faces
from app.core.decimation import cluster, face_normals, quadric
from app.core.mesh import InvalidMeshError, Mesh, clean


def normalize_scale(mesh: Mesh) -> Mesh:
    """Centre at the area-weighted centroid and scale to unit surface area.

    HKS with t scaled by 1/λ and per-vertex normalisation is already scale invariant; a unit-area
    mesh keeps eigenvalues O(1)..O(n), which keeps the shift-invert solve well conditioned.
    """
    areas = mesh.face_areas()
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    centre = (areas[:, None] * centroids).sum(axis=0) / areas.sum()
    return Mesh((mesh.vertices - centre) / np.sqrt(areas.sum()), mesh.faces)


SUBDIVISIONS = ("midpoint", "loop")


def to_resolution(
    mesh: Mesh, target_vertices: int, tolerance: float = 1.5, subdivision: str = "midpoint",
    prefilter_length: float = 0.0, prefilter_ramp: tuple[float, float] = (0.0, 0.0),
) -> Mesh:
    """Canonical resolution policy: bring the vertex count within [target/tol, target*tol].

    Coarse meshes are subdivided at edge midpoints (each step ~4x the vertices); fine meshes are
    simplified with quadric error decimation (fast-simplification), which keeps the shape at a bounded
    cost. The eigen-solve then always runs at about `target_vertices`, so descriptors of the same shape
    at different input resolutions agree and the cost of describing is bounded.

    Midpoint rather than Loop subdivision: it adds sample points and leaves the surface exactly where
    it is, whereas Loop's limit surface shrinks a coarse mesh (a 500-face SHREC'11 mesh loses 13-16 %
    of its area, most of it on thin limbs and small protrusions that tell classes apart). Measured on
    SHREC'11, midpoint retrieves better than Loop on clean and on noisy queries (docs/results.md).
    The Taubin step that follows in describe() rounds the flat facets. subdivision="loop" keeps the
    first policy for comparison.
    """
    if subdivision not in SUBDIVISIONS:
        raise ValueError(f"subdivision must be one of {', '.join(SUBDIVISIONS)}, not {subdivision!r}")
    if target_vertices <= 0:
        return mesh
    out = mesh
    while out.n_vertices * tolerance < target_vertices:
        if subdivision == "loop":
            v, f = trimesh.remesh.subdivide_loop(out.vertices, out.faces, iterations=1)
        else:
            v, f = trimesh.remesh.subdivide(out.vertices, out.faces)
        out = Mesh(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64))
    if out.n_vertices > target_vertices * tolerance:
        out = simplify(out, target_vertices, tolerance, prefilter_length, prefilter_ramp)
    return out


# Edge-collapse rungs (aggressiveness), gentlest first; each continues from the last kept result.
# At unit area one agg=3 pass reaches the target on most meshes; open scans can stop short (pizza:
# 24.9k -> 1.8k vertices) and a second pass or a rung at agg=5 finishes the job.
QUADRIC_RUNGS: tuple[float, ...] = (3.0, 3.0, 5.0)
# A rung's result is kept only if it lost less than this fraction of the area: on CAD meshes with
# thin parts, a more aggressive rung collapses whole walls (trimesh boolean.glb: agg=5 keeps 44 %).
AREA_LOSS_MAX = 0.05
# When the first pass ends above STALLED x target, edge collapse is blocked by the topology
# (fans of slivers, non-manifold seams: one more pass on a 20k-vertex CAD part costs ~1 s for a
# few % fewer vertices): go straight to clustering.
STALLED = 3.0
# Above PRECLUSTER_ABOVE x target, cluster to PRECLUSTER_TO x target first: edge collapse costs
# ~13 us and ~450 B per vertex (2.2M vertices: 37 s, +0.9 GB), clustering a fraction of that. But
# clustering leaves a surface whose pieces meet at single vertices, and edge collapse then tears it
# apart: a smooth 164k-vertex sphere came out in 37 pieces at the old 60x (one watertight piece by
# edge collapse alone, 0.49 s), and the realworld turbine blade (99.5k vertices) lost its
# self-retrieval (a re-triangulated copy ranked it 94th of 106; 1st without the clustering). So only
# inputs edge collapse cannot afford go through it: 500x (500k vertices: ~3-5 s, ~225 MB).
PRECLUSTER_ABOVE = 500
PRECLUSTER_TO = 30
# When edge collapse stalls, cluster to REGRID_TO x target (folds dropped) and collapse again (_regrid).
REGRID_TO = 3


def simplify(
    mesh: Mesh, target_vertices: int, tolerance: float = 1.5, prefilter_length: float = 0.0,
    prefilter_ramp: tuple[float, float] = (0.0, 0.0),
) -> Mesh:
    """Decimate to at most `tolerance` x `target_vertices` vertices, whatever the topology.

    The chain: (huge inputs) vertex clustering to PRECLUSTER_TO x target; quadric edge collapse,
    one pass at agg=3 and, while above 1.1 x target, further rungs (QUADRIC_RUNGS) that must keep
    the area (AREA_LOSS_MAX); if that leaves the mesh above the band, vertex clustering to the target
    (any topology, always reduces). Every result is cleaned: no degenerate or duplicate faces, no
    debris, so every vertex keeps a positive lumped area. Decimation runs on a unit-area copy
    (fast-simplification's thresholds are absolute: a 35k-vertex scan in millimetres stalled at 34k
    vertices; at unit area one agg=3 pass reaches 1,000) and the result is scaled back.
    Raises InvalidMeshError when no stage brings the mesh within the band.
    """
    unit, centre, size = _unit_area(mesh)
    work: Mesh | None
    try:
        if unit.n_vertices > PRECLUSTER_ABOVE * target_vertices:
            unit = _unfolded(clean(cluster(unit, PRECLUSTER_TO * target_vertices)))
        # the low-pass after the clustering: its cost grows with the vertex count and the ratio; its
        # ramp reads the input's own ratio (clustering to 30x is far above any ramp's end)
        ratio = mesh.n_vertices / target_vertices
        unit = prefilter(unit, target_vertices, ramp_length(prefilter_length, ratio, prefilter_ramp))
        work = _collapse(unit, target_vertices)
    except InvalidMeshError:  # cleaning refused what edge collapse left (pieces, slivers)
        work = None
    if work is None or work.n_vertices > tolerance * target_vertices:
        work = _regrid(unit, target_vertices)  # edge collapse stalled: regrid, then collapse again
    if work is None or work.n_vertices > tolerance * target_vertices:
        try:
            # last resort: any topology, always reduces (folds kept: at the target's own resolution,
            # dropping them opened holes that cost more than the tears; realworld self-retrieval
            # of re-triangulated copies fell from 0.47 to 0.40)
            work = clean(cluster(unit, target_vertices))
        except InvalidMeshError as exc:
            why = f"the mesh could not be simplified to about {target_vertices} vertices: {exc}"
            raise InvalidMeshError(why) from exc
    if work.n_vertices > tolerance * target_vertices:
        raise InvalidMeshError(
            f"the mesh could not be simplified to about {target_vertices} vertices ({mesh.n_vertices} -> "
            f"{work.n_vertices}): neither edge collapse nor vertex clustering got there"
        )
    return Mesh(work.vertices * size + centre, work.faces)


def _regrid(unit: Mesh, target_vertices: int) -> Mesh | None:
    """When edge collapse stalls (CAD: fans of slivers, non-manifold seams): cluster to REGRID_TO x the
    target, drop the folds there (small holes at that resolution), and edge-collapse to the target from
    that regular grid. None when that fails too, or loses more than AREA_LOSS_MAX of the area (then
    clustering straight to the target). On the realworld corpus, re-triangulated copies find
    themselves more often this way than with direct clustering (docs/results.md)."""
    try:
        out = _collapse(_unfolded(clean(cluster(unit, REGRID_TO * target_vertices))), target_vertices)
    except InvalidMeshError:
        return None
    # the folds dropped must leave small holes only (trimesh cycloidal.ply: 42 % of its area gone)
    return out if out.area() >= (1.0 - AREA_LOSS_MAX) * unit.area() else None


def _unfolded(mesh: Mesh) -> Mesh:
    """A clustered mesh (the pre-pass's, or the regrid's) without the faces on edges shared by more
    than two faces (where clustering folded the surface onto itself). Edge collapse tears the surface
    apart at such edges: a smooth 164k-vertex sphere clustered to 30k and collapsed to 1k came out in
    37 pieces, in one without them (small holes instead: area 0.999). Unchanged when nothing is
    folded, or nothing would be left."""
    folded = nonmanifold_faces(mesh.faces)
    if not folded.any() or folded.all():
        return mesh
    try:
        return clean(Mesh(mesh.vertices, mesh.faces[~folded]))
    except InvalidMeshError:  # too little left: keep the folds
        return mesh


def _collapse(mesh: Mesh, target_vertices: int) -> Mesh:
    """Quadric edge collapse along QUADRIC_RUNGS until within 1.1 x target (a further pass on a
    small mesh costs milliseconds; an eigen-solve at 1.35x the vertices costs 2.5x)."""
    work = clean(quadric(mesh, target_vertices, QUADRIC_RUNGS[0]))
    for aggressiveness in QUADRIC_RUNGS[1:]:
        if work.n_vertices <= 1.1 * target_vertices or work.n_vertices > STALLED * target_vertices:
            break
        try:
            nxt = clean(quadric(work, target_vertices, aggressiveness))
        except InvalidMeshError:  # the rung left nothing usable: keep what we have
            continue
        if nxt.n_vertices < work.n_vertices and nxt.area() >= (1.0 - AREA_LOSS_MAX) * work.area():
            work = nxt
    return work


def _unit_area(mesh: Mesh) -> tuple[Mesh, np.ndarray, float]:
    """(copy centred at the bounding-box centre with unit area, centre (3,), sqrt(area))."""
    centre = 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))
    fn = face_normals(mesh)  # chunked: Mesh.area() makes an (f, 3, 3) copy
    size = float(np.sqrt(0.5 * np.sqrt(np.einsum("ij,ij->i", fn, fn)).sum()))
    return Mesh((mesh.vertices - centre) / size, mesh.faces), centre, size


def perturb(mesh: Mesh, noise_to_signal: float, seed: int = 0) -> Mesh:
    """Gaussian vertex noise with variance = noise_to_signal * variance of the coordinates (paper Fig. 3)."""
    rng = np.random.default_rng(seed)
    sigma = np.sqrt(noise_to_signal * mesh.vertices.var(axis=0))
    return Mesh(mesh.vertices + rng.normal(size=mesh.vertices.shape) * sigma, mesh.faces)
