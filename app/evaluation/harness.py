"""The evaluation harness: Table 2 (NN FT ST E DCG mAP d) of a labelled folder, every shape a query.

One call describes every mesh once (worker processes, on-disk cache, see app.evaluation.cache), then
for each row fits a vocabulary on the folder's keypoint descriptors, encodes every shape, ranks by
L1 distance and scores with app.core.metrics. Baselines (Shape-DNA, D2) run in the same loop on the
same shapes. Variant lines measure what a deployed service meets, each against its clean, fit-on-DIR
line (Δ mAP): a frozen vocabulary (`vocabulary`), a vocabulary fit on half of the classes
(`fit_on="half"`), noisy queries against a clean database (`noise`, the paper's Fig. 3), and the
meshes of another folder as queries (`queries`, e.g. another triangulation of every shape, see
app.evaluation.sets). `fusion` weights add, per BoF row, a row fused with Shape-DNA (app.core.fusion).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from app.core import metrics
from app.core.baselines import D2_BINS, SHAPE_DNA_COUNT, euclidean_distance, shape_dna
from app.core.descriptor import RUNS, dimension
from app.core.keypoints import KeypointFilter
from app.core.pipeline import DescribeParams, ShapeDescription
from app.core.resolution import SUBDIVISIONS as SUBDIVISIONS  # the --subdivision choices
from app.core.vocabulary import EncodeParams, Vocabulary, l1_distance
from app.evaluation import adaptive, sets
from app.evaluation import cache as cache_mod
from app.evaluation.results import (
    BASELINES,
    PRESETS,
    ROW_NAMES,
    EvaluationError,
    EvaluationOptions,
    EvaluationResult,
    RowResult,
    mean_over_seeds,
)


@dataclass(frozen=True)
class Row:
    name: str
    kind: str  # bof | shape-dna | d2
    describe: DescribeParams
    run: str = "run5"
    fusion: float | None = None  # Shape-DNA weight of a fused BoF row
    area_weighted: bool | None = None  # the BoF's integral; None: the options'
    mode: str | None = None  # vector quantisation; None: the options'


def build_rows(options: EvaluationOptions) -> list[Row]:
    unknown = [r for r in options.rows if r not in ROW_NAMES]
    if unknown:
        raise EvaluationError(f"unknown row(s) {', '.join(unknown)}; choose from {', '.join(ROW_NAMES)}")
    flt = KeypointFilter(enabled=options.keypoint_filter)
    if any(w < 0 for w in options.fusion):
        raise EvaluationError("--fusion weights must be >= 0")
    try:
        base = DescribeParams(
            k=options.k, target_vertices=options.target_vertices, time_range=options.time_range,
            smoothing=options.smoothing, smoothing_target=options.smoothing_target,
            antialias=options.antialias,
            antialias_start=options.antialias_ramp[0], antialias_full=options.antialias_ramp[1],
            smoothing_weights=options.smoothing_weights, laplacian=options.laplacian, remesh=options.remesh,
            subdivision=options.subdivision, fill_holes=options.fill_holes, keypoint_filter=flt,
        )
    except ValueError as exc:  # e.g. an unknown subdivision
        raise EvaluationError(str(exc)) from exc
    rows = []
    for name in options.rows:
        if name in RUNS:
            bof = [Row(name, "bof", base, name)]
        elif name == "paper":
            paper = replace(base, k=300, target_vertices=0, smoothing=0, time_range="spectrum",
                            laplacian="cotangent", remesh=False, fill_holes=0.0)
            # eq. 8, a sum over vertices, hard VQ (eq. 6): as the paper's Table 2 was computed
            bof = [Row(name, "bof", paper, "run5", area_weighted=False, mode="hard")]
        else:
            rows.append(Row(name, name, base))
            continue
        rows += bof + [replace(bof[0], name=f"{name} + {w:g} DNA", fusion=w) for w in options.fusion]
    return rows


def evaluate(directory: str | Path, options: EvaluationOptions | None = None) -> EvaluationResult:
    """Describe, encode and score every shape of `directory` (labels.csv: file,class[,split])."""
    options = options or EvaluationOptions()
    start = time.perf_counter()
    database = _read_folder(directory)
    files, labels = database.files, database.labels
    query_set = _read_folder(options.queries) if options.queries is not None else None
    rows = build_rows(options)
    frozen = _load_frozen(options, rows)
    if options.fit_on not in ("all", "half"):
        raise EvaluationError(f"--fit-on must be 'all' or 'half', not {options.fit_on!r}")
    if options.mode not in ("hard", "soft"):
        raise EvaluationError(f"--mode must be 'hard' or 'soft', not {options.mode!r}")
    if not options.sigma_scale > 0:
        raise EvaluationError(f"--sigma-scale must be > 0, not {options.sigma_scale!r}")
    if options.noise < 0:
        raise EvaluationError("--noise must be >= 0")
    if options.seeds < 1:
        raise EvaluationError("--seeds must be at least 1")

    cache = cache_mod.DescriptionCache(options.cache_dir)
    clean, noisy = cache_mod.Variant(), cache_mod.Variant(options.noise, options.seed)
    stats = cache_mod.DescribeStats()
    variants = [clean] + ([noisy] if options.noise > 0 else [])
    want_d2 = any(r.kind == "d2" for r in rows)
    descs: dict[tuple[DescribeParams, cache_mod.Variant], list[ShapeDescription]] = {}
    cross: dict[DescribeParams, list[ShapeDescription]] = {}  # the query folder's descriptions
    try:
        for params in dict.fromkeys(r.describe for r in rows):
            served = [r.name for r in rows if r.describe == params and r.fusion is None]
            label = "describe for " + ", ".join(served)  # which rows wait for this pass
            for variant in variants:
                cache_mod.describe_all(files, params, cache, variant, want_d2, options.workers,
                                       options.progress, stats, label)
                descs[params, variant] = cache_mod.load_descriptions(files, params, cache, variant)
            if query_set is not None:
                cache_mod.describe_all(query_set.files, params, cache, clean, False, options.workers,
                                       options.progress, stats, f"{label} ({Path(query_set.root).name})")
                cross[params] = cache_mod.load_descriptions(query_set.files, params, cache, clean)
    except cache_mod.DescribeFailure as exc:
        raise EvaluationError(str(exc)) from exc

    result = EvaluationResult(str(directory), len(files), len(set(labels.tolist())), options)
    result.describe = _describe_summary(descs, stats)
    fitted: dict[tuple, Vocabulary] = {}  # a fused row reuses its plain row's k-means vocabularies
    for row in rows:
        db = descs[row.describe, clean]
        queries = descs[row.describe, noisy] if options.noise > 0 else None
        other = None
        if query_set is not None and row.kind != "d2":  # D2 is not computed for the query folder
            other = CrossSet(Path(query_set.root).name, cross[row.describe], query_set.labels,
                             sets.counterparts(database, query_set))
        try:
            if row.kind == "bof":
                result.rows += _bof_lines(row, db, queries, labels, options, frozen, other, fitted)
            else:
                d2 = {v: cache_mod.load_d2(files, cache, v) for v in variants} if row.kind == "d2" else {}
                result.rows += _baseline_lines(row, db, queries, d2, labels, options, other)
        except ValueError as exc:  # e.g. too few distinct descriptors for the vocabulary size
            raise EvaluationError(f"row {row.name}: {exc}") from exc
    result.seconds = time.perf_counter() - start
    return result


@dataclass(frozen=True)
class CrossSet:
    """Another folder's descriptions as queries against the database (app.evaluation.sets)."""

    name: str
    descriptions: list[ShapeDescription]
    labels: np.ndarray  # (q,)
    pairs: np.ndarray  # (q,) database counterpart left out of each ranking, or all -1


def _read_folder(directory: str | Path) -> sets.Folder:
    try:
        folder = sets.read_folder(directory)
    except sets.FolderError as exc:
        raise EvaluationError(str(exc)) from exc
    if len(set(folder.labels.tolist())) < 2:
        raise EvaluationError(f"retrieval needs at least two classes in {directory}/labels.csv")
    return folder


def _load_frozen(options: EvaluationOptions, rows: Sequence[Row]) -> Vocabulary | None:
    if options.vocabulary is None:
        return None
    try:
        vocab = Vocabulary.load(options.vocabulary)
    except (OSError, ValueError, KeyError) as exc:
        raise EvaluationError(f"cannot load the vocabulary at {options.vocabulary}: {exc}") from exc
    wrong = [r.name for r in rows if r.kind == "bof" and r.run != vocab.run]
    if wrong:
        raise EvaluationError(
            f"the vocabulary at {options.vocabulary} encodes {vocab.run}; rows {', '.join(wrong)} use "
            f"another descriptor (pass --runs {vocab.run} plus any of {', '.join(PRESETS + BASELINES)})"
        )
    return vocab


def _bof_lines(
    row: Row, db: list[ShapeDescription], queries: list[ShapeDescription] | None, labels: np.ndarray,
    options: EvaluationOptions, frozen: Vocabulary | None, other: CrossSet | None = None,
    fitted: dict[tuple, Vocabulary] | None = None,
) -> list[RowResult]:
    """The row's lines, each the mean over `options.seeds` k-means seeds (single-seed mAPs in details).

    k-means seeds alone move mAP by ~0.3 points on SHREC'11, so comparisons finer than that need seeds > 1.
    """
    area_weighted = options.area_weighted if row.area_weighted is None else row.area_weighted
    mode = options.mode if row.mode is None else row.mode
    params = EncodeParams(mode=mode, sigma_scale=options.sigma_scale,
                          keypoints_only=options.keypoints_only,
                          area_weighted=area_weighted, fusion=row.fusion is not None)
    fitted = {} if fitted is None else fitted
    per_seed = [_bof_lines_one_seed(row, db, queries, labels, options, params, options.seed + i, other,
                                    fitted) for i in range(options.seeds)]
    lines = [mean_over_seeds(same) for same in zip(*per_seed, strict=True)]
    by_name = {line.name: line for line in lines}
    for line in lines:  # Δ mAP against the mean clean line, not against one seed's
        line.reference = by_name[line.reference.name] if line.reference is not None else None
    # one vocabulary, no seed; a fused row only at the weight of the vocabulary's own scales (what the
    # service serves with it)
    if frozen is not None and (row.fusion is None or _fused_at(frozen, row.fusion)):
        _check_frozen_encoding(frozen, row, params, options)
        lines[1:1] = _frozen_lines(row, frozen, db, queries, labels, options, params, lines[0], other)
    return lines


def _frozen_lines(
    row: Row, frozen: Vocabulary, db: list[ShapeDescription], queries: list[ShapeDescription] | None,
    labels: np.ndarray, options: EvaluationOptions, params: EncodeParams, clean: RowResult,
    other: CrossSet | None,
) -> list[RowResult]:
    """What the service serves with the frozen vocabulary: the clean line (Δ against the self-fit
    one), then the noisy and other-folder queries, each Δ against the served clean line."""
    name = f"{row.name} [frozen {Path(options.vocabulary or '').name}]"
    served = _score_bof(name, row, frozen, db, db, labels, params, time.perf_counter(), clean)
    out = [served]
    if queries is not None:
        out.append(_score_bof(f"{name} [noise {options.noise:g}]", row, frozen, db, queries, labels, params,
                              time.perf_counter(), served))
    if other is not None:
        out.append(_score_bof(f"{name} [queries {other.name}]", row, frozen, db, other.descriptions, labels,
                              params, time.perf_counter(), served, other))
    if options.adaptive_fusion and row.fusion is not None:
        out += _adaptive_lines(out, row, frozen, db, queries, labels, params, other)
    return out


def _adaptive_lines(
    fixed: list[RowResult], row: Row, vocab: Vocabulary, db: list[ShapeDescription],
    queries: list[ShapeDescription] | None, labels: np.ndarray, params: EncodeParams, other: CrossSet | None,
) -> list[RowResult]:
    """The frozen fused lines `fixed` (clean, noisy, other folder) re-ranked as the service does
    (app.evaluation.adaptive: the fusion re-rank, and a query with a rim ranked as a piece), each Δ
    against its fixed-fusion line."""
    scales = vocab.fusion
    if scales is None or scales.weight <= 0:
        return []
    db_vec = np.stack([vocab.encode(d, params) for d in db])
    sets_: list[tuple[list[ShapeDescription], np.ndarray, np.ndarray, CrossSet | None]] = [
        (db, labels, np.arange(len(db)), None)]
    if queries is not None:
        sets_.append((queries, labels, np.arange(len(db)), None))
    if other is not None:
        sets_.append((other.descriptions, other.labels, other.pairs, other))
    out = []
    for line, (q_descs, q_labels, left_out, cross) in zip(fixed, sets_, strict=True):
        t0 = time.perf_counter()
        q_vec = np.stack([vocab.encode(d, params) for d in q_descs])
        rims = adaptive.rims_of(q_descs)  # a closed query weighs its Shape-DNA as the fixed fusion at least
        # a query with a rim is ranked as the service ranks a piece (by partial score), as /search and
        # /models/{id}/similar do
        rank = adaptive.ranks(q_vec, db_vec, left_out, vocab.size, scales.weight, rims=rims,
                              noises=adaptive.noises_of(q_descs), query_locals=[d.local for d in q_descs],
                              db_locals=[d.local for d in db])
        if cross is None:
            scores = metrics.retrieval_scores(rank, labels)
        else:
            scores = sets.cross_scores(rank, q_labels, labels, cross.pairs)[0]
        out.append(RowResult(f"{line.name} [adaptive]", "bof", scores, line.d,
                             time.perf_counter() - t0, line, dict(line.details, adaptive=True)))
    return out


def _check_frozen_encoding(
    vocab: Vocabulary, row: Row, params: EncodeParams, options: EvaluationOptions
) -> None:
    """A frozen fused line uses the vocabulary's BoF scale, fit on BoFs encoded one way: scoring BoFs
    encoded another way would weigh its two parts off and give a figure nobody serves."""
    changes = vocab.fusion_encoding_changes(params) if row.fusion is not None else {}
    if changes:
        flags = " ".join(f"--{k.replace('_', '-')} {fit}" for k, (fit, _) in changes.items()
                         if k in ("mode", "sigma_scale"))
        raise EvaluationError(
            f"the vocabulary at {options.vocabulary} has a fusion scale fit with "
            f"{ {k: fit for k, (fit, _) in changes.items()} }, row {row.name} encodes with "
            f"{ {k: now for k, (_, now) in changes.items()} }: evaluate with its encoding "
            f"({flags or 'the same encode flags'}) or refit the vocabulary"
        )


def _fused_at(vocab: Vocabulary, weight: float) -> bool:
    """Whether `vocab` carries fusion scales fit for the Shape-DNA weight `weight`."""
    return vocab.fusion is not None and vocab.fusion.weight == weight


def _bof_lines_one_seed(
    row: Row, db: list[ShapeDescription], queries: list[ShapeDescription] | None, labels: np.ndarray,
    options: EvaluationOptions, params: EncodeParams, seed: int, other: CrossSet | None = None,
    fitted: dict[tuple, Vocabulary] | None = None,
) -> list[RowResult]:
    meta = {"row": row.name}
    t0 = time.perf_counter()
    vocab = _fit(db, row, options, params, seed, fitted, "all", meta)
    main = _score_bof(row.name, row, vocab, db, db, labels, params, t0)
    out = [main]
    if options.fit_on == "half":
        t1 = time.perf_counter()
        classes = sorted(set(labels.tolist()))[::2]  # every other class, in name order
        subset = [d for d, lab in zip(db, labels, strict=True) if lab in classes]
        half = _fit(subset, row, options, params, seed, fitted, "half")
        name = f"{row.name} [fit on {len(classes)}/{len(set(labels.tolist()))} classes]"
        out.append(_score_bof(name, row, half, db, db, labels, params, t1, main))
    if queries is not None:
        name = f"{row.name} [noise {options.noise:g}]"
        out.append(_score_bof(name, row, vocab, db, queries, labels, params, time.perf_counter(), main))
    if other is not None:
        name = f"{row.name} [queries {other.name}]"
        out.append(_score_bof(name, row, vocab, db, other.descriptions, labels, params, time.perf_counter(),
                              main, other))
    return out


def _fit(db: list[ShapeDescription], row: Row, options: EvaluationOptions, params: EncodeParams,
         seed: int, fitted: dict[tuple, Vocabulary] | None, subset: str,
         metadata: dict | None = None) -> Vocabulary:
    """k-means vocabulary on `db` (memoised in `fitted` by describe parameters, run, seed and
    subset); for a fused row, plus its fusion scales fit on the same shapes."""
    key = (row.describe, row.run, seed, subset)
    vocab = (fitted or {}).get(key)
    if vocab is None:
        vocab = Vocabulary.fit(db, size=options.vocabulary_size, run=row.run, seed=seed, metadata=metadata)
        if fitted is not None:
            fitted[key] = vocab
    return vocab if row.fusion is None else vocab.with_fusion(db, params, weight=row.fusion)


def _score_bof(
    name: str, row: Row, vocab: Vocabulary, db: list[ShapeDescription], queries: list[ShapeDescription],
    labels: np.ndarray, params: EncodeParams, t0: float, reference: RowResult | None = None,
    other: CrossSet | None = None,
) -> RowResult:
    """Encode database and queries with `vocab`; row i of the distances = query i vs the database
    (queries: the database's own shapes, noisy ones in its order, or `other`'s)."""
    db_bof = np.stack([vocab.encode(d, params) for d in db])  # (N, v) or (N, v + c) fused
    q_bof = db_bof if queries is db else np.stack([vocab.encode(d, params) for d in queries])
    distances = l1_distance(q_bof, db_bof)  # (q, N)
    if other is None:
        scores, per_class = metrics.scores_and_breakdown(distances, labels)
    else:
        scores, per_class = sets.cross_scores(distances, other.labels, labels, other.pairs)
    return RowResult(name, "bof", scores, dimension(row.run), time.perf_counter() - t0, reference,
                     {"run": row.run, "vocabulary_size": vocab.size, "describe": row.describe.fingerprint(),
                      "encode": asdict(params), "fusion": row.fusion,
                      "vector_length": vocab.dimension(params), "per_class": per_class})


def _baseline_lines(
    row: Row, db: list[ShapeDescription], queries: list[ShapeDescription] | None,
    d2: dict, labels: np.ndarray, options: EvaluationOptions, other: CrossSet | None = None,
) -> list[RowResult]:
    def score(name: str, q: np.ndarray, base: np.ndarray, t0: float, ref: RowResult | None,
              cross: CrossSet | None = None) -> RowResult:
        dist = euclidean_distance(q, base) if row.kind == "shape-dna" else l1_distance(q, base)
        dim = SHAPE_DNA_COUNT if row.kind == "shape-dna" else D2_BINS
        scores = (metrics.retrieval_scores(dist, labels) if cross is None
                  else sets.cross_scores(dist, cross.labels, labels, cross.pairs)[0])
        return RowResult(name, row.kind, scores, dim, time.perf_counter() - t0, ref,
                         {"describe": row.describe.fingerprint()})

    t0 = time.perf_counter()
    if row.kind == "shape-dna":  # eigenvalues of the unit-area canonical mesh: area = 1
        base = np.stack([shape_dna(d.eigenvalues) for d in db])
        noisy = np.stack([shape_dna(d.eigenvalues) for d in queries]) if queries is not None else None
    else:
        variants = list(d2)
        base, noisy = d2[variants[0]], (d2[variants[1]] if len(variants) > 1 else None)
    main = score(row.name, base, base, t0, None)
    out = [main]
    if noisy is not None:
        out.append(score(f"{row.name} [noise {options.noise:g}]", noisy, base, time.perf_counter(), main))
    if other is not None and row.kind == "shape-dna":
        q = np.stack([shape_dna(d.eigenvalues) for d in other.descriptions])
        out.append(score(f"{row.name} [queries {other.name}]", q, base, time.perf_counter(), main, other))
    return out


def _describe_summary(descs: dict, stats: cache_mod.DescribeStats) -> dict:
    per_params = {}
    for (params, variant), ds in descs.items():
        key = params.fingerprint() + (f" | noisy queries {variant.noise:g}" if variant.noise else "")
        per_params[key] = {
            "mean_vertices": float(np.mean([d.n_vertices for d in ds])),
            "mean_keypoints": float(np.mean([d.keypoints.sum() for d in ds])),
        }
    return {"computed": stats.computed, "cached": stats.cached, "d2_computed": stats.d2_computed,
            "seconds": stats.seconds, "descriptions": per_params}
