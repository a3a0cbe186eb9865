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
    status: str
    model: ModelPublic


class JobPublic(BaseModel):
    id: int
    kind: str
    state: str
    model_id: int | None
    attempts: int
    error: str | None
    timings: dict[str, Any]
    payload: dict[str, Any]
    created_at: str
    updated_at: str

    @classmethod
    def of(cls, j: JobRecord) -> JobPublic:
        return cls.model_validate(j, from_attributes=True)  # lease_until, worker: internal, not copied


class JobAccepted(BaseModel):
    job_id: int
    state: str


class SearchHit(BaseModel):
    model_id: int
    name: str
    label: str | None
    distance: float = Field(description="L1 distance between BoF vectors (+ scaled Shape-DNA when fused)")
    rank: int


class SearchResponse(BaseModel):
    data: list[SearchHit]
    count: int
    vocabulary_id: int
    seconds: dict[str, float] = Field(description="wall time per stage")


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


class Health(BaseModel):
    status: str


class Readiness(BaseModel):
    ready: bool
    checks: dict[str, Any]
