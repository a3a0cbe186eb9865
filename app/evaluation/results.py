"""The evaluation's options and result types: what the harness produces and the report prints.

Both app.evaluation.harness and app.evaluation.report import from here, so the report depends on the
results, not on the harness, and no import runs in a circle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.core.descriptor import RUNS
from app.core.keypoints import KeypointFilter
from app.core.pipeline import DescribeParams
from app.core.vocabulary import EncodeParams

PRESETS: tuple[str, ...] = ("paper",)  # run5 at the raw resolution, unsmoothed: as the paper computes it
BASELINES: tuple[str, ...] = ("shape-dna", "d2")
ROW_NAMES: tuple[str, ...] = RUNS + PRESETS + BASELINES
# the paper row solves at each mesh's own resolution (tens of seconds per 50k-vertex scan): asked for by
# name or with "all", never by default
DEFAULT_ROWS: tuple[str, ...] = RUNS + BASELINES
DEFAULT_CACHE = Path(".cache/describe")


class EvaluationError(ValueError):
    """The evaluation cannot run as asked; the message says why."""


@dataclass(frozen=True)
class EvaluationOptions:
    rows: tuple[str, ...] = DEFAULT_ROWS
    vocabulary_size: int = 64
    mode: str = EncodeParams.mode  # hard (eq. 6) | soft (eq. 5)
    sigma_scale: float = EncodeParams.sigma_scale  # soft VQ width, in the vocabulary's σ
    keypoints_only: bool = False  # BoF over the keypoints instead of every vertex
    area_weighted: bool = EncodeParams.area_weighted  # BoF as an integral over the surface (eq. 7)
    keypoint_filter: bool = KeypointFilter.enabled
    target_vertices: int = DescribeParams.target_vertices
    k: int = DescribeParams.k  # eigenpairs
    time_range: str = DescribeParams.time_range  # weyl | spectrum (the paper's t_min)
    smoothing: int = DescribeParams.smoothing  # Taubin steps (λ, μ, λ ...)
    smoothing_weights: str = DescribeParams.smoothing_weights  # one of smoothing.WEIGHTS
    smoothing_target: float = DescribeParams.smoothing_target  # > 0: adaptive, to this roughness
    antialias: float = DescribeParams.antialias  # > 0: low-pass before decimation, canonical edges
    antialias_ramp: tuple[float, float] = (DescribeParams.antialias_start, DescribeParams.antialias_full)
    fill_holes: float = DescribeParams.fill_holes  # largest cap closed, fraction of the area
    laplacian: str = DescribeParams.laplacian  # cotangent | intrinsic (intrinsic Delaunay)
    remesh: bool = DescribeParams.remesh  # isotropic remeshing at the canonical resolution
    subdivision: str = DescribeParams.subdivision  # midpoint | loop
    vocabulary: Path | None = None  # frozen vocabulary directory: adds a "frozen" line per row
    fit_on: str = "all"  # all | half: "half" adds a line with a vocabulary fit on half the classes
    noise: float = 0.0  # > 0: adds a line with noisy queries against the clean database
    queries: Path | None = None  # labelled folder: adds a line with its meshes as queries
    fusion: tuple[float, ...] = ()  # Shape-DNA weights: adds a fused row per BoF row and weight
    adaptive_fusion: bool = False  # frozen fused lines also re-ranked as served (app.evaluation.adaptive)
    seed: int = 0
    seeds: int = 1  # k-means seeds seed, seed+1, ...: BoF lines report the mean (and the spread)
    per_class: bool = False  # print where each clean BoF row loses (per-class mAP, first-tier intruders)
    workers: int = 2
    cache_dir: Path = DEFAULT_CACHE
    progress: bool = True


@dataclass
class RowResult:
    """One line of the table: mean scores, descriptor length d, seconds (fit + encode + rank + score),
    and for a variant line the clean line it is compared with (Δ mAP = this - reference)."""

    name: str
    kind: str
    scores: dict[str, float]
    d: int
    seconds: float
    reference: RowResult | None = None
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def delta_map(self) -> float | None:
        return None if self.reference is None else self.scores["mAP"] - self.reference.scores["mAP"]


def mean_over_seeds(lines: Sequence[RowResult]) -> RowResult:
    """One line from the same line under several seeds: mean scores, total seconds."""
    first = lines[0]
    if len(lines) == 1:
        return first
    scores = {m: float(np.mean([line.scores[m] for line in lines])) for m in first.scores}
    maps = [line.scores["mAP"] for line in lines]
    details = {**first.details, "seeds": len(lines), "mAP_per_seed": maps, "mAP_sd": float(np.std(maps)),
               "per_class": merge_breakdowns([line.details["per_class"] for line in lines])}
    return RowResult(first.name, first.kind, scores, first.d, sum(line.seconds for line in lines),
                     first.reference, details)


def merge_breakdowns(breakdowns: Sequence[dict[str, dict]]) -> dict[str, dict]:
    """Per-class mAP averaged over seeds; intruder counts summed over them."""
    merged = {}
    for cls in breakdowns[0]:
        counts: dict[str, int] = {}
        for b in breakdowns:
            for other, n in b[cls]["intruders"].items():
                counts[other] = counts.get(other, 0) + n
        merged[cls] = {"mAP": float(np.mean([b[cls]["mAP"] for b in breakdowns])),
                       "intruders": dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))}
    return merged


@dataclass
class EvaluationResult:
    directory: str
    shapes: int
    classes: int
    options: EvaluationOptions
    rows: list[RowResult] = field(default_factory=list)
    describe: dict = field(default_factory=dict)
    seconds: float = 0.0
