"""describe(mesh) -> ShapeDescription: the whole per-shape computation, done once per mesh.

The description keeps the full normalised HKS h(x) (n, m), not just p(x), so every descriptor run
and every vocabulary can be applied later without recomputing eigenpairs.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from app.core import hks as hks_mod
from app.core.doubling import DOUBLE_RIM, doubled
from app.core.holes import fill_holes
from app.core.keypoints import KeypointFilter, detect
from app.core.laplacian import LAPLACIANS, laplacian
from app.core.mesh import InvalidMeshError, Mesh
from app.core.packing import pack_float32, unpack_float32
from app.core.partial import LocalParams, LocalSignature, free_boundary, local_signature, rim_length
from app.core.remeshing import isotropic_remesh
from app.core.resolution import SUBDIVISIONS, normalize_scale, to_resolution
from app.core.roughness import displacement_correlation, smooth_until
from app.core.smoothing import WEIGHTS, taubin
from app.core.spectrum import Spectrum, SpectrumError, smallest_eigenpairs

DESCRIPTION_FORMAT = 3  # 3: + the local signature (app/core/partial.py); 2 (HKS packed), 1 still load
LOCAL = LocalParams()  # fixed: a model's and a query's local signatures must share one grid


@dataclass(frozen=True)
class DescribeParams:
    """Parameters of the per-shape computation (those that change h(x) or the keypoints)."""

    k: int = 300  # eigenpairs
    m: int = 100  # time scales
    # t_min from the computed λ_k (the paper's). "weyl" (λ_k ≈ 4πk) is the same for every triangulation
    # and helps unsmoothed meshes, but once the mesh is smoothed it retrieves worse across
    # triangulations (docs/results.md)
    time_range: str = "spectrum"
    target_vertices: int = 1000  # canonical resolution; 0 keeps the input resolution
    # Taubin steps (λ, μ, λ ...: 12 = 6 pairs) at the canonical resolution; 0 = none. Enough to absorb
    # vertex noise without losing on any other collection; more smoothing helps noisy queries but costs
    # on other triangulations and decimated scans (docs/results.md)
    smoothing: int = 12
    # capped-area (the default), area, intrinsic, cotangent or uniform Taubin weights
    # (app.core.smoothing). capped-area: each neighbour by the area of the faces on its edge, each face
    # counted at most as the mesh's median face: intrinsic (face areas), so a crowded side does not pull,
    # and a CAD part's few large faces do not drag their vertices. It is the weighting that held on every
    # collection measured: cotangent weights do not even out a triangulation, uncapped areas lose on
    # rigid parts, uniform weights depend on the connectivity (docs/results.md)
    smoothing_weights: str = "capped-area"
    # > 0: adaptive smoothing, an evaluation option (`shapebag evaluate --smoothing-target`), not a
    # service setting: a mesh that reaches the canonical resolution by decimation gets Taubin pairs only
    # until its roughness (app.core.roughness) is at most this, `smoothing` steps at most; a subdivided
    # mesh always gets `smoothing` steps. It keeps clean scans' detail but leaves noisy queries
    # unlike the clean collection they are matched against (docs/results.md, "Full-resolution
    # columns"). 0: `smoothing` steps for every mesh
    smoothing_target: float = 0.0
    # before decimation, a low-pass at the input's resolution over this many canonical edge lengths
    # (app.core.antialias), so detail the canonical mesh cannot show, and vertex noise, do not alias
    # into it: with it, full-resolution columns gain clean and under noise at once (docs/results.md,
    # "Full-resolution columns"); 0: none. Meshes that are subdivided (SHREC'11) never see it
    antialias: float = 0.5
    # its strength ramps with the decimation ratio n_input / target: none up to antialias_start x,
    # full from antialias_full x on. Mild decimations alias little, and there the low-pass only rounds
    # the shape against a collection described without it (docs/results.md, "Full-resolution columns")
    antialias_start: float = 4.0
    antialias_full: float = 12.0
    # intrinsic (cotangent weights of the intrinsic Delaunay triangulation: the same operator on a
    # Delaunay mesh, far less dependent on the triangulation elsewhere) | cotangent (the paper's)
    laplacian: str = "intrinsic"
    # isotropic remeshing at the canonical resolution (app.core.remeshing): triangulation-proof, but it
    # spends vertices on the area that noise adds, so noisy queries retrieve far worse; an option
    remesh: bool = False
    subdivision: str = "midpoint"  # how coarse meshes reach the canonical resolution: midpoint | loop
    # close each boundary loop whose centroid cap adds at most this fraction of its piece's area
    # (app.core.holes); 0 leaves every hole open. A scanner's holes reflect the heat at their rims and
    # change the signature; closing the small ones helps scan-like shapes and leaves closed meshes
    # untouched (docs/results.md)
    fill_holes: float = 0.05
    solver: str = "auto"  # auto | dense | sparse
    keypoint_filter: KeypointFilter = field(default_factory=KeypointFilter)

    def __post_init__(self) -> None:
        if self.subdivision not in SUBDIVISIONS:
            known = ", ".join(SUBDIVISIONS)
            raise ValueError(f"subdivision must be one of {known}, not {self.subdivision!r}")
        if self.smoothing_weights not in WEIGHTS:
            raise ValueError(f"smoothing_weights must be one of {', '.join(WEIGHTS)}, "
                             f"not {self.smoothing_weights!r}")
        if self.laplacian not in LAPLACIANS:
            raise ValueError(f"laplacian must be one of {', '.join(LAPLACIANS)}, not {self.laplacian!r}")
        if not self.antialias >= 0.0:
            raise ValueError(f"antialias must be >= 0, not {self.antialias!r}")
        if not 0.0 <= self.antialias_start <= self.antialias_full:
            raise ValueError(f"the antialias ramp needs 0 <= start <= full, not "
                             f"{self.antialias_start!r} .. {self.antialias_full!r}")
        if not self.smoothing_target >= 0.0:
            raise ValueError(f"smoothing_target must be >= 0, not {self.smoothing_target!r}")
        if not 0.0 <= self.fill_holes < 1.0:
            raise ValueError(f"fill_holes must be in [0, 1), not {self.fill_holes!r}")
        if self.time_range not in hks_mod.TIME_RANGES:
            known = ", ".join(hks_mod.TIME_RANGES)
            raise ValueError(f"time_range must be one of {known}, not {self.time_range!r}")

    def fingerprint(self) -> str:
        """A stable string naming these parameters (cache keys)."""
        d = asdict(self)
        f = d.pop("keypoint_filter")
        for option in ("smoothing_target", "antialias"):  # off: descriptions named as before the option
            if not d[option]:
                del d[option]
        if "antialias" not in d:  # no low-pass: its ramp changes nothing
            del d["antialias_start"], d["antialias_full"]
        parts = [f"{k}={v}" for k, v in sorted(d.items()) if k != "solver"]
        parts += [f"kf.{k}={v}" for k, v in sorted(f.items())]
        return ";".join(parts)


def fingerprint_fields(fingerprint: str) -> dict[str, str]:
    """{name: value} of a DescribeParams.fingerprint() string ("k=300;smoothing=12;kf.enabled=False")."""
    return dict(part.split("=", 1) for part in fingerprint.split(";") if "=" in part)


@dataclass(frozen=True)
class ShapeDescription:
    """What the index needs of one shape.

    hks         : (n, m) float32, normalised HKS h(x) (eq. 4) at the canonical resolution
    weights     : (n,) float32, lumped vertex areas of the unit-area mesh (sum = 1)
    keypoints   : (n,) bool, filtered feature points
    eigenvalues : (k,) float64, of the unit-area mesh (Shape-DNA comes for free)
    input_vertices : vertex count of the mesh as given
    input_noise : corr(δ, W δ) of the mesh as given (app.core.roughness.displacement_correlation):
                  negative when its finest scale is vertex noise; NaN when unknown (saved before it)
    seconds     : per-stage wall time
    local       : sampled local signature for partial matching (app.core.partial, on the query grid:
                  a model uses its leading slopes); None in descriptions saved before format 3
    """

    hks: np.ndarray
    weights: np.ndarray
    keypoints: np.ndarray
    eigenvalues: np.ndarray
    input_vertices: int
    input_noise: float = float("nan")
    seconds: dict[str, float] = field(default_factory=dict)
    local: LocalSignature | None = None

    @property
    def n_vertices(self) -> int:
        return int(self.hks.shape[0])

    def save(self, path: str | Path) -> None:
        """Write a .npz (no pickle); the HKS table packed losslessly (app/core/packing.py)."""
        local = {} if self.local is None else local_members(self.local)
        with open(path, "wb") as fh:
            np.savez_compressed(
                fh, hks_packed=pack_float32(self.hks), hks_shape=np.asarray(self.hks.shape, dtype=np.int64),
                weights=self.weights, keypoints=self.keypoints,
                eigenvalues=self.eigenvalues, input_vertices=np.int64(self.input_vertices),
                input_noise=np.float64(self.input_noise),
                format=np.int64(DESCRIPTION_FORMAT), **local,
            )

    @classmethod
    def load(cls, path: str | Path) -> ShapeDescription:
        """Read what save() writes, or a format-1 file (its HKS table stored as it is) or a format-2
        one (no local signature)."""
        with np.load(path, allow_pickle=False) as z:
            found = int(z["format"])
            if found not in (1, 2, DESCRIPTION_FORMAT):
                raise ValueError(f"description format {found} is not {DESCRIPTION_FORMAT}")
            if found == 1:
                hks = z["hks"]
            else:
                hks = unpack_float32(z["hks_packed"], tuple(int(x) for x in z["hks_shape"]))
            return cls(
                hks=hks, weights=z["weights"], keypoints=z["keypoints"].astype(bool),
                eigenvalues=z["eigenvalues"], input_vertices=int(z["input_vertices"]), local=_local(z),
                input_noise=_input_noise(z),
            )


def local_members(local: LocalSignature) -> dict[str, Any]:
    """The npz members a description stores of its local signature (what _local reads back)."""
    out: dict[str, Any] = {"local_slopes": local.slopes, "local_area": local.area, "local_valid": local.valid,
           "local_rim": np.asarray(local.rim)}
    if local.vertex is not None:
        out["local_vertex"] = local.vertex
    if local.level is not None:
        out["local_level"] = local.level
    if local.surface is not None:
        out["local_surface"] = local.surface
    return out


def load_local_and_noise(path: str | Path) -> tuple[LocalSignature | None, float]:
    """What the re-rankings read of a saved description, without its HKS table: the local signature
    (None before format 3) and the input displacement correlation (NaN: saved before it was recorded)."""
    with np.load(path, allow_pickle=False) as z:
        return _local(z), _input_noise(z)


def _input_noise(z: np.lib.npyio.NpzFile) -> float:
    return float(z["input_noise"]) if "input_noise" in z.files else float("nan")


def _local(z: np.lib.npyio.NpzFile) -> LocalSignature | None:
    if "local_slopes" not in z.files:
        return None
    vertex = z["local_vertex"] if "local_vertex" in z.files else None  # stored since the matched region
    level = z["local_level"] if "local_level" in z.files else None  # stored since the level's weight
    surface = z["local_surface"] if "local_surface" in z.files else None  # stored since the piece fit
    return LocalSignature(slopes=z["local_slopes"], area=z["local_area"], valid=z["local_valid"],
                          rim=float(z["local_rim"]), vertex=vertex, level=level, surface=surface)


def canonical_mesh(mesh: Mesh, params: DescribeParams) -> Mesh:
    """The mesh whose vertices the description is of (before smoothing moves them): the canonical
    resolution, small holes closed. vertices (n, 3), faces (f, 3)."""
    return canonical_with_rim(mesh, params)[0]


def canonical_with_rim(mesh: Mesh, params: DescribeParams) -> tuple[Mesh, np.ndarray]:
    """(canonical_mesh(mesh, params), rim (n,) bool): the vertices on a free boundary of the canonical
    resolution, closed or not, and the centres of the caps that closed one (heat reflected there
    before the cap, and a cap is not the surface that was there)."""
    fine = to_resolution(mesh, params.target_vertices, subdivision=params.subdivision,
                         prefilter_length=params.antialias,
                         prefilter_ramp=(params.antialias_start, params.antialias_full))
    closed = fill_holes(fine, params.fill_holes)[0]
    return closed, _rim_mask(fine.faces, len(fine.vertices), len(closed.vertices))


def _rim_mask(faces: np.ndarray, n_open: int, n_closed: int) -> np.ndarray:
    """(n_closed,) the free-boundary vertices of the open mesh (n_open vertices), then its caps' centres."""
    return np.concatenate([free_boundary(faces, n_open), np.ones(n_closed - n_open, dtype=bool)])


def describe(mesh: Mesh, params: DescribeParams | None = None) -> ShapeDescription:
    """Mesh (already validated and cleaned by mesh.load_mesh) -> ShapeDescription."""
    params = params or DescribeParams()
    return describe_filters(mesh, params, [params.keypoint_filter])[0]


def describe_filters(
    mesh: Mesh, params: DescribeParams, filters: Sequence[KeypointFilter]
) -> list[ShapeDescription]:
    """One eigen-solve, one description per keypoint filter (the harness compares filters; the
    solve is the cost). Description i equals describe(mesh, replace(params, keypoint_filter=filters[i]))."""
    clock = _Clock()
    noise = _input_noise_of(mesh, clock)
    fine, rim = canonical_with_rim(mesh, params)
    return _from_canonical(mesh, noise, fine, rim, params, filters, clock)


def describe_canonical(mesh: Mesh, fine: Mesh, rim: np.ndarray, params: DescribeParams) -> ShapeDescription:
    """describe(mesh, params) from (fine, rim) = canonical_with_rim(mesh, params), for a caller that
    needs both (the explain view): the mesh is resampled once. The rim is required: `fine` has its
    small holes capped, and only canonical_with_rim knows where the caps are; so is the mesh as given,
    whose vertex count and noise the description records."""
    clock = _Clock()
    noise = _input_noise_of(mesh, clock)
    return _from_canonical(mesh, noise, fine, rim, params, [params.keypoint_filter], clock)[0]


def _input_noise_of(mesh: Mesh, clock: _Clock) -> float:
    """The mesh as given's displacement correlation, timed as the stage "noise". Measured there, not on
    the canonical mesh: its low-pass and decimation hide the noise that still moves the HKS (the
    fusion weighs a noisy closed query's Shape-DNA more, app.core.fusion)."""
    noise = displacement_correlation(mesh)
    clock.lap("noise")
    return noise


def _from_canonical(mesh: Mesh, input_noise: float, fine: Mesh, rim: np.ndarray, params: DescribeParams,
                    filters: Sequence[KeypointFilter], clock: _Clock) -> list[ShapeDescription]:
    input_vertices = mesh.n_vertices
    # resampling and smoothing are scale-free: one normalisation, after them, gives unit area
    smoothed = smooth(fine, input_vertices, params)
    # remeshing after smoothing: an even sampling of a noisy surface spends its vertices on the
    # noise's extra area (remeshing first loses badly on noisy queries: docs/results.md)
    if params.remesh:
        smoothed = isotropic_remesh(smoothed, params.target_vertices)
    work = normalize_scale(smoothed)
    clock.lap("resample")
    n = work.n_vertices
    # remeshing moves the vertices off the canonical mesh's: its rim is the remeshed mesh's open boundary
    rim_now = rim if len(rim) == n else _rim_mask(work.faces, n, n)
    # the rim's length as resampled, before smoothing: smoothing pulls a puncture's vertices (a face
    # that decimation collapsed to a point, ~1e-8 across, left open by fill_holes) an edge apart, and a
    # few such read as a piece's rim (docs/partial.md, "Punctures are not rims")
    rim_value = (rim_length(fine.vertices, fine.faces, rim) if rim_now is rim
                 else rim_length(work.vertices, work.faces, rim_now))
    # a surface that is rim nearly everywhere (what one viewer sees: the front of every limb) is solved
    # on its double, at unit area: each half-tube's heat is then its tube's (app.core.doubling), and no
    # slope needs the rim's distrust
    solve = Mesh(*doubled(work.vertices / np.sqrt(2.0), work.faces)) if rim_value > DOUBLE_RIM else work
    stiffness, mass = laplacian(solve.vertices, solve.faces, params.laplacian)
    clock.lap("laplacian")
    try:
        spectrum = smallest_eigenpairs(stiffness, mass, params.k, method=params.solver)
        clock.lap("eigen")
        times = hks_mod.time_scales(spectrum.eigenvalues, params.m, params.time_range)
    except SpectrumError as exc:  # the mesh's, not the server's: a clear refusal (422), never retried
        raise InvalidMeshError(f"the mesh's Laplace-Beltrami spectrum could not be computed: {exc}") from exc
    own = spectrum if solve is work else Spectrum(spectrum.eigenvalues, spectrum.eigenvectors[:n])
    raw = hks_mod.heat_kernel_signature(own, times)  # (n, m): the surface's own vertices
    h = hks_mod.normalize(raw)
    clock.lap("hks")
    masks = [detect(raw, work.faces, flt) for flt in filters]
    clock.lap("keypoints")
    areas = mass.diagonal()[:n]
    hks32, weights = h.astype(np.float32), areas.astype(np.float32)
    trusted = rim_now if solve is work else np.zeros(n, dtype=bool)
    local = local_signature(own, solve.vertices[:n], work.faces, areas, trusted, LOCAL,
                            measured_rim=rim_value)
    local = replace(local, surface=work.vertices.astype(np.float16))  # unit area, the piece's own
    clock.lap("local")
    return [
        ShapeDescription(hks=hks32, weights=weights, keypoints=mask, eigenvalues=spectrum.eigenvalues,
                         input_vertices=input_vertices, input_noise=input_noise, seconds=dict(clock.laps),
                         local=local)
        for mask in masks
    ]


def smooth(fine: Mesh, input_vertices: int, params: DescribeParams) -> Mesh:
    """The canonical mesh as the eigen-solve sees it: `smoothing` Taubin steps, or, when adaptive
    (smoothing_target > 0) and the mesh was not subdivided, only as many as its roughness needs."""
    if params.smoothing_target > 0 and fine.n_vertices <= input_vertices:
        return smooth_until(fine, params.smoothing_target, params.smoothing, params.smoothing_weights)[0]
    return taubin(fine, params.smoothing, params.smoothing_weights)


class _Clock:
    def __init__(self) -> None:
        self.laps: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.laps[name] = now - self._t
        self._t = now
