"""Request/response schemas, named by direction (ModelCreate in, ModelPublic out, ...)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field

from app.storage.jobs import JobRecord
from app.storage.models import ModelRecord


class ErrorBody(BaseModel):
    code: str
    message: str


class ErrorResponse(BaseModel):
    error: ErrorBody


class ModelCreate(BaseModel):
    """The multipart fields of POST /models besides `file` (documented here; read from the stream)."""

    name: str | None = Field(
        None,
        min_length=1,
        max_length=200,
        description="display name; default: the file name without extension",
    )
    label: str | None = Field(
        None, min_length=1, max_length=100, description="class label, used for filtering and evaluation"
    )
    metadata: dict[str, Any] = Field(default_factory=dict, description="free JSON object")


class ModelPublic(BaseModel):
    id: int
    name: str
    label: str | None
    status: str
    error: str | None
    n_vertices: int | None
    file_type: str
    size_bytes: int
    sha256: str
    metadata: dict[str, Any]
    created_at: str
    updated_at: str
    stored_bytes: int | None = Field(
        None,
        description="bytes the model holds in the data directory: its mesh file, description and cached"
        " thumbnails (GET /models/{id} only; a mesh shared by identical uploads counts for each)",
    )
    variants: list[dict[str, Any]] | None = Field(
        None, description="likely variants (model_id, name, relation, confidence), on GET /models/{id} only"
    )

    @classmethod
    def of(cls, m: ModelRecord) -> ModelPublic:
        return cls.model_validate(m, from_attributes=True)


class ModelsPublic(BaseModel):
    data: list[ModelPublic]
    count: int = Field(description="total matching the filters (not just this page)")


class LabelCount(BaseModel):
    label: str
    models: int = Field(description="models carrying this label, in any status")


class LabelsPublic(BaseModel):
    data: list[LabelCount]


class ModelAccepted(BaseModel):
    model_id: int
    job_id: int | None = Field(description="null when the identical content was already stored")
    status: str = Field(description="the model's status: queued | ready | failed")
    model: ModelPublic
    variants: list[dict[str, Any]] | None = Field(
        None, description="likely variants (model_id, name, relation, confidence): known once the model is"
        " described; GET /models/{id}/variants has the evidence"
    )
    duplicate_of: int | None = Field(
        None, description="the stored model these bytes already are (its name and label are kept)"
    )
    note: str | None = Field(None, description="what happened, when it is not what was asked")


# Facts a job records beside its timings (one JSON column in storage): the API shows them as `result`, so
# `timings` holds seconds only. A stored "result" object is taken as it is; these keys are older rows' form.
# the `partial` option of POST /search and GET /models/{id}/similar
PARTIAL: dict[str, bool | None] = {"auto": None, "true": True, "false": False}
JOB_RESULT_KEYS = frozenset({"vocabulary_id", "models", "object_rows", "pruned_versions",
                             "encoded_after_swap", "note"})


def split_job_timings(stored: dict[str, Any]) -> tuple[dict[str, float], dict[str, Any]]:
    """(seconds per stage, everything else) of a job's stored timings."""
    result: dict[str, Any] = dict(stored.get("result") or {})
    timings: dict[str, float] = {}
    for key, value in stored.items():
        if key == "result":
            continue
        if key in JOB_RESULT_KEYS or isinstance(value, bool) or not isinstance(value, int | float):
            # counts were stored as floats beside the seconds: show them as the integers they are
            result[key] = int(value) if isinstance(value, float) and value.is_integer() else value
        else:
            timings[key] = float(value)
    return timings, result


JOB_STATUS = "queued | running | done | failed"
STATE_ALIAS = Field(description="the same as status (its former name), kept for old clients", deprecated=True)


class JobPublic(BaseModel):
    id: int
    kind: str
    status: str = Field(description=JOB_STATUS)
    state: str = STATE_ALIAS
    model_id: int | None
    attempts: int
    error: str | None
    timings: dict[str, float] = Field(description="seconds per stage")
    result: dict[str, Any] = Field(description="what the job produced, e.g. vocabulary_id and models")
    payload: dict[str, Any]
    created_at: str
    updated_at: str

    @classmethod
    def of(cls, j: JobRecord) -> JobPublic:
        timings, result = split_job_timings(j.timings)
        return cls(  # lease_until, worker: internal, not copied
            id=j.id, kind=j.kind, status=j.state, state=j.state, model_id=j.model_id, attempts=j.attempts,
            error=j.error, timings=timings, result=result, payload=j.payload, created_at=j.created_at,
            updated_at=j.updated_at,
        )


class JobAccepted(BaseModel):
    job_id: int
    status: str = Field(description=JOB_STATUS)
    state: str = STATE_ALIAS


class MatchedRegion(BaseModel):
    """Where a piece matched in a model: the model's local-signature samples (at most 256)."""

    vertices: list[int] = Field(
        description="sample vertices of the model, as indices into the `vertices` of GET"
        " /models/{id}/explain (the mesh at the canonical resolution the description is of); each sample"
        " stands for the surface nearer to it than to any other sample"
    )
    weights: list[float] = Field(
        description="per sample, the share of the query's surface whose best match it is (within the"
        " match tolerance, at the winning scale); they sum to `forward`, and 0 means nothing matched there"
    )


class PieceFitPublic(BaseModel):
    """A piece fitted onto a model by a similarity (moved, rescaled, possibly mirrored), then ICP."""

    lies_on: bool = Field(description="the fit shows the query lies on this model's surface: a piece of it")
    covered: float = Field(ge=0.0, le=1.0, description="share of the query's samples within one vertex"
                           " spacing of the model's surface (at the canonical resolution) once fitted")
    share: float = Field(ge=0.0, description="the share of the model's area the fitted query stands for")
    mirrored: bool = Field(description="the fit mirrors the query")


class SearchHit(BaseModel):
    model_id: int
    name: str
    label: str | None
    distance: float = Field(description="L1 distance between BoF vectors (+ scaled Shape-DNA when fused)")
    rank: int
    rerank_distance: float | None = Field(
        None, description="the query-adaptive fusion's distance, which whole-shape hits are ordered by when"
        " the vectors are fused (SHAPEBAG_FUSION_RERANK, on by default), but for a distinct nearest match"
        " (index distance under 0.9 times the second's), which stays first whatever its own; null when the"
        " index's L1 order is served (a piece, pure BoF, or the re-rank turned off)"
    )
    forward: float | None = Field(
        None, ge=0.0, le=1.0, description="share of the query's surface found in the model (partial matching;"
        " null when the model was described before local signatures were stored)"
    )
    reverse: float | None = Field(
        None, ge=0.0, le=1.0, description="share of the model's surface the query covers (partial matching)"
    )
    partial: bool = Field(
        False, description="true when the query was taken for a piece and the hits re-ranked by partial match"
    )
    region: MatchedRegion | None = Field(
        None, description="a piece's hits (`partial` true): the region of the model the query matched; null"
        " for a whole query, or a model described before its sample vertices were stored (re-ingest it)"
    )
    matched_object: int | None = Field(
        None, ge=1, description="the model is a multi-object file (a print plate, an assembly) and the query"
        " matched this one of its objects (1 = its largest distinct object; `distance` is to that object);"
        " null when the model's whole shape matched (docs/partial.md, \"Parts of multi-object files\")"
    )
    fit: PieceFitPublic | None = Field(
        None, description="a piece's hits (`partial` true) that it was fitted onto: whether it lies on the"
        " model, with the numbers (docs/partial.md, \"A piece fitted onto its source\"); null when not"
        " fitted (a whole query, a candidate the fit's screen passed over, or a model described before"
        " its surface was stored)"
    )
    relation: str | None = Field(
        None, description="the verified variant relation of the query to this model, when there is one"
        " (GET /models/{id}/similar: stored links; POST /search: verified for the query within the query"
        " pool's deadline): identical | moved | rescaled | mirrored | retriangulated | part_of | contains"
    )
    evidence: dict[str, Any] | None = Field(
        None, description="POST /search: the numbers behind `relation` (confidence, chamfer, hausdorff,"
        " forward, reverse, scale, mirrored, transform: the query onto this model, ...)"
    )


class VariantDecision(BaseModel):
    decision: str = Field(description="keep_both | not_variant")
    note: str | None = Field(None, max_length=500)


class VariantDecisionPublic(VariantDecision):
    model_id: int
    other_id: int
    decided_at: str


class VariantPublic(BaseModel):
    """How another stored model relates to this one, with the numbers behind it."""

    model_id: int = Field(description="the other model")
    name: str
    relation: str = Field(
        description="identical | moved | rescaled | mirrored | retriangulated | part_of (this model is a"
        " part of the other) | contains (this model holds the other, `copies` times)"
    )
    confidence: float = Field(description="in [0, 1]; its meaning is measured by benchmarks.variants_detect")
    chamfer: float = Field(description="symmetric mean surface distance / bounding-box diagonal")
    hausdorff: float = Field(description="symmetric largest surface distance / bounding-box diagonal")
    forward: float = Field(description="fraction of this model's surface within 1 % of the other's")
    reverse: float = Field(description="fraction of the other's surface within 1 % of this model's")
    scale: float = Field(description="uniform scale taking this model onto the other")
    mirrored: bool
    same_triangles: bool
    transform: list[list[float]] = Field(description="4 x 4, this model (or its matched part) onto the other")
    copies: int
    lies_on_other: bool | None = Field(
        None, description="one-sided test (re-triangulated when the symmetric distances are too large):"
        " true when this model's vertices lie on the other's surface (a coarser copy), false when the"
        " other's lie on this one; null when the test was not needed"
    )
    resolution: float | None = Field(None, description="the lying model's mean edge / diagonal")
    slack: float | None = Field(None, description="the length its tolerances grow with / diagonal")
    vertex_gap: float | None = Field(
        None, description="99 % of its vertices lie within this of the other surface (/ diagonal)"
    )
    uncovered: float | None = Field(None, description="90 % of the other surface lies within this of it")
    decision: VariantDecisionPublic | None = Field(None, description="the latest reviewer decision")


class VariantsPublic(BaseModel):
    data: list[VariantPublic]
    count: int


class PartialWork(BaseModel):
    """How much of the partial matching a search did: its two steps stop at their deadlines."""

    coarse_read: int = Field(
        description="stored models the coarse pass read (a piece's: the global index's nearest, compared"
        " on an eighth of the query's samples to pick candidates)"
    )
    coarse_of: int = Field(description="models it was to read (0: no coarse pass: a whole query, or a"
                           " collection no larger than the global candidates)")
    coarse_cut: bool = Field(description="true when its deadline stopped the coarse pass before the end")
    scored: int = Field(description="candidates the full match reached (a piece's candidates, or a whole"
                        " query's k hits; one without a local signature counts, with no score)")
    scored_of: int = Field(description="candidates it was to score")
    score_cut: bool = Field(
        description="true when its deadline left candidates unscored: they follow the scored ones in their"
        " global order, and the vote counted among fewer"
    )
    fitted: int = Field(0, description="candidates a piece was fitted onto (a similarity fit that shows"
                        " it lies on the model: the hit's `fit`); 0 for a whole query")
    fitted_of: int = Field(0, description="candidates chosen to be fitted (the most promising screens and"
                           " the best scores)")
    fit_cut: bool = Field(False, description="true when the fits' deadline left candidates unscreened or"
                          " chosen ones unfitted: those get no `fit`")


class SearchResponse(BaseModel):
    data: list[SearchHit]
    count: int
    vocabulary_id: int
    seconds: dict[str, float] = Field(
        description="wall time per stage (a dotted name is a step of the stage before the dot:"
        " partial.coarse, partial.score, ...)"
    )
    partial: PartialWork | None = Field(
        None, description="how much of the partial matching was done (a piece's re-ranking, or a whole"
        " query's forward / reverse scores); null when the query has no local signature, or for a stored"
        " model's similar search that is not ranked as a piece"
    )


class VocabularyRebuild(BaseModel):
    size: int = Field(64, ge=2, le=4096, description="number of geometric words")
    run: str = Field("run5", description="descriptor selection (Table 1 run1..run5)")
    seed: int = Field(default=0, ge=0, lt=2**32, description="k-means seed (NumPy seeds are 32-bit)")


class VocabularyPublic(BaseModel):
    """The active vocabulary; every field but the counts is null before the first one exists."""

    id: int | None = None
    words: int | None = None
    run: str | None = None
    trained_on_descriptors: int | None = None
    created_at: str | None = None
    indexed_models: int = 0
    versions: int = 0
    metadata: dict[str, Any] = Field(default_factory=dict)
    # the background refit on the collection (SHAPEBAG_VOCABULARY_REFIT_AT): ready models at which the
    # next is due; null when refits are off
    next_refit_at: int | None = None


class Health(BaseModel):
    status: str


class Readiness(BaseModel):
    ready: bool
    checks: dict[str, Any]


class ShapeExplained(BaseModel):
    """One shape at the canonical resolution, its vertices coloured by word (GET /models/{id}/explain)."""

    model_id: int | None = Field(description="null for an uploaded query")
    name: str
    label: str | None
    vertices: list[float] = Field(
        description="x, y, z of each vertex, flattened (n * 3): centred, turned as the thumbnail (y up)"
    )
    faces: list[int] = Field(description="vertex indices of each triangle, flattened (f * 3)")
    words: list[int] = Field(description="the visual word of each vertex (hard quantisation), n values")
    keypoints: list[int] = Field(description="vertex indices of the keypoints")
    bof: list[float] = Field(description="the Bag-of-Features histogram, one value per word")


class WordContribution(BaseModel):
    word: int
    shape: float = Field(description="the word's BoF value on the explained shape")
    against: float = Field(description="its value on the other shape")
    contribution: float = Field(description="|shape - against|: this word's part of the BoF L1 distance")


class Explanation(BaseModel):
    vocabulary_id: int
    words: int = Field(description="words in the vocabulary")
    shape: ShapeExplained
    against: ShapeExplained | None
    bof_l1: float | None = Field(description="L1 distance between the two BoF histograms")
    distance: float | None = Field(description="a hit's `distance`: the index's L1 (BoF, fused with DNA)")
    top_words: list[WordContribution] = Field(description="the words that separate the shapes most")
