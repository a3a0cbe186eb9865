"""`shapebag evaluate DIR`: print Table 2 for a labelled folder (labels.csv: file,class[,split])."""

from __future__ import annotations

import argparse
from pathlib import Path

from app.cli import CommandError
from app.core.hks import TIME_RANGES
from app.core.laplacian import LAPLACIANS
from app.core.smoothing import WEIGHTS
from app.core.vocabulary import EncodeParams
from app.evaluation.harness import SUBDIVISIONS, evaluate
from app.evaluation.report import format_table, write_json
from app.evaluation.results import DEFAULT_CACHE, DEFAULT_ROWS, ROW_NAMES, EvaluationError, EvaluationOptions


def _ramp(text: str) -> tuple[float, float]:
    """ "START,FULL" -> (start, full), 0 <= start <= full."""
    try:
        start, full = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START,FULL (two numbers), not {text!r}") from None
    if not 0.0 <= start <= full:
        raise argparse.ArgumentTypeError(f"expected 0 <= START <= FULL, not {text!r}")
    return start, full

def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "evaluate",
        help="retrieval statistics (NN FT ST E DCG mAP) of a labelled folder, every shape a query",
        description="Describe every mesh of DIR (cached), then print Table 2: one row per descriptor run, "
        "preset and baseline. Variant lines (frozen vocabulary, --fit-on half, --noise) show Δ mAP "
        "against their clean line.",
    )
    p.add_argument("directory", type=Path, help="folder holding labels.csv (file,class[,split])")
    p.add_argument("--runs", default=",".join(DEFAULT_ROWS),
                   help=f"comma-separated rows, or 'all': {', '.join(ROW_NAMES)} (default: all but paper, "
                   "which solves run5 at each mesh's own resolution as the paper did: tens of seconds per "
                   "mesh of 50k vertices)")
    p.add_argument("--vocabulary-size", type=int, default=64, help="words per vocabulary (default 64)")
    p.add_argument("--mode", choices=("hard", "soft"), default=EncodeParams.mode,
                   help=f"vector quantisation: hard (eq. 6) or soft (eq. 5; default {EncodeParams.mode})")
    p.add_argument("--sigma-scale", type=float, default=EncodeParams.sigma_scale,
                   help="soft VQ width σ, as a multiple of the vocabulary's median quantisation distance "
                   f"(default {EncodeParams.sigma_scale:g})")
    scope = p.add_mutually_exclusive_group()
    scope.add_argument("--keypoints-only", action="store_true", help="BoF over the keypoints only")
    scope.add_argument("--all-vertices", action="store_true", help="BoF over every vertex (default)")
    p.add_argument("--area-weighted", action=argparse.BooleanOptionalAction,
                   default=EvaluationOptions.area_weighted,
                   help="each vertex counts by its area in the BoF (eq. 7, an integral over the surface); "
                   "--no-area-weighted: each vertex by 1 (eq. 8)")
    flt = p.add_mutually_exclusive_group()
    flt.add_argument("--filter", dest="keypoint_filter", action="store_true", default=None,
                     help="filter the keypoints by persistence and contrast"
                     + (" (default)" if EvaluationOptions.keypoint_filter else ""))
    flt.add_argument("--no-filter", dest="keypoint_filter", action="store_false",
                     help="keep every 2-ring HKS maximum as a keypoint"
                     + ("" if EvaluationOptions.keypoint_filter else " (default)"))
    p.add_argument("--target-vertices", type=int, default=EvaluationOptions.target_vertices,
                   help="canonical resolution of the eigen-solve (0 keeps the input resolution)")
    p.add_argument("--k", type=int, default=EvaluationOptions.k,
                   help="eigenpairs (default %(default)s, the paper's)")
    p.add_argument("--time-range", choices=TIME_RANGES, default=EvaluationOptions.time_range,
                   help="t_min from Weyl's law or from the computed λ_k (spectrum: the paper's; "
                   "default %(default)s)")
    p.add_argument("--smoothing", type=int, default=EvaluationOptions.smoothing,
                   help="Taubin steps before the eigen-solve, λ and μ alternating (0: none; "
                   "default %(default)s)")
    p.add_argument("--smoothing-target", type=float, default=EvaluationOptions.smoothing_target,
                   metavar="R", help="adaptive smoothing: a mesh that was not subdivided gets Taubin pairs "
                   "until its roughness is at most R, --smoothing steps at most (0: --smoothing steps for "
                   "every mesh)")
    p.add_argument("--antialias", type=float, default=EvaluationOptions.antialias, metavar="L",
                   help="before decimation, a low-pass at the input's resolution over L canonical edge "
                   "lengths (0: none; default %(default)s)")
    p.add_argument("--antialias-ramp", type=_ramp, default=EvaluationOptions.antialias_ramp,
                   metavar="START,FULL", help="the low-pass ramps with the decimation ratio: none up to "
                   "START x, full from FULL x (default %(default)s)")
    p.add_argument("--smoothing-weights", choices=WEIGHTS, default=EvaluationOptions.smoothing_weights,
                   help="Taubin weights: intrinsic (intrinsic Delaunay cotangent), cotangent (extrinsic, "
                   "clipped at 0), area (faces on each edge), capped-area (the same, each face at most the "
                   "median face) or uniform (default %(default)s)")
    p.add_argument("--fill-holes", type=float, default=EvaluationOptions.fill_holes, metavar="F",
                   help="close holes whose cap adds at most F of the area (0: none; default %(default)s)")
    p.add_argument("--laplacian", choices=LAPLACIANS, default=EvaluationOptions.laplacian,
                   help="cotangent (the paper's) or intrinsic (intrinsic Delaunay; default %(default)s)")
    p.add_argument("--remesh", action=argparse.BooleanOptionalAction, default=EvaluationOptions.remesh,
                   help="isotropic remeshing at the canonical resolution (default %(default)s)")
    p.add_argument("--subdivision", choices=SUBDIVISIONS, default=EvaluationOptions.subdivision,
                   help="how coarse meshes are refined to the canonical resolution (default %(default)s)")
    p.add_argument("--vocabulary", type=Path, metavar="DIR",
                   help="also encode with this frozen vocabulary (centers.npy + vocabulary.json); a fused "
                        "row at the weight its scales were fit for gets the line the service would serve")
    p.add_argument("--fit-on", choices=("all", "half"), default="all",
                   help="half: also fit a vocabulary on half of the classes and report the mAP shift")
    p.add_argument("--noise", type=float, default=0.0, metavar="NSR",
                   help="also query with noisy meshes (noise variance / coordinate variance, e.g. 0.01)")
    p.add_argument("--queries", type=Path, metavar="QDIR",
                   help="also query with the meshes of QDIR (labels.csv; same classes) against DIR; files "
                   "named as in DIR are the same shapes and are left out of their own ranking")
    p.add_argument("--fusion", default="", metavar="W[,W]",
                   help="per BoF row, also a row fused with Shape-DNA at each weight W (e.g. 0.5,1)")
    p.add_argument("--adaptive-fusion", action="store_true",
                   help="with --vocabulary: also score each frozen fused line ranked as the service "
                   "ranks it: the query-adaptive fusion (SHAPEBAG_FUSION_RERANK), and a query with a rim "
                   "(a piece, an open scan) by partial matching")
    p.add_argument("--seed", type=int, default=0, help="k-means and noise seed")
    p.add_argument("--seeds", type=int, default=1, metavar="N",
                   help="average BoF lines over N k-means seeds (seed, seed+1, ...) and show their spread")
    p.add_argument("--per-class", action="store_true",
                   help="also print, per BoF line (noisy and --queries lines too), the classes below "
                        "99.5 %% mAP and who intrudes into them")
    p.add_argument("--workers", type=int, default=2, help="describing processes (default 2)")
    p.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE, help=f"default {DEFAULT_CACHE}")
    p.add_argument("--json", type=Path, metavar="OUT", help="write the table and settings as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    rows = tuple(r.strip() for r in args.runs.split(",") if r.strip())
    rows = ROW_NAMES if rows == ("all",) else rows
    if not rows:
        raise CommandError("--runs names no row")
    if args.vocabulary_size < 2:
        raise CommandError("--vocabulary-size must be at least 2")
    if args.workers < 1:
        raise CommandError("--workers must be at least 1")
    if args.target_vertices < 0:
        raise CommandError("--target-vertices must be >= 0")
    if args.k < 2:
        raise CommandError("--k must be at least 2")
    if args.smoothing < 0:
        raise CommandError("--smoothing must be >= 0")
    try:
        fusion = tuple(float(w) for w in args.fusion.split(",") if w.strip())
    except ValueError as exc:
        raise CommandError(f"--fusion takes comma-separated weights, not {args.fusion!r}") from exc
    options = EvaluationOptions(
        rows=rows,
        vocabulary_size=args.vocabulary_size,
        mode=args.mode,
        sigma_scale=args.sigma_scale,
        keypoints_only=args.keypoints_only,
        area_weighted=args.area_weighted,
        keypoint_filter=(EvaluationOptions.keypoint_filter if args.keypoint_filter is None
                         else args.keypoint_filter),
        target_vertices=args.target_vertices,
        k=args.k,
        time_range=args.time_range,
        smoothing=args.smoothing,
        smoothing_weights=args.smoothing_weights, smoothing_target=args.smoothing_target,
        antialias=args.antialias, antialias_ramp=args.antialias_ramp,

        fill_holes=args.fill_holes,
        laplacian=args.laplacian,
        remesh=args.remesh,
        subdivision=args.subdivision,
        vocabulary=args.vocabulary,
        fit_on=args.fit_on,
        noise=args.noise,
        queries=args.queries,
        fusion=fusion,
        adaptive_fusion=args.adaptive_fusion,
        seed=args.seed,
        seeds=args.seeds,
        per_class=args.per_class,
        workers=args.workers,
        cache_dir=args.cache_dir,
        progress=not args.quiet,
    )
    try:
        result = evaluate(args.directory, options)
    except EvaluationError as exc:
        raise CommandError(str(exc)) from exc
    print(format_table(result))
    if args.json:
        print(f"wrote {write_json(result, args.json)}")
    return 0
