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
        return cls(
            id=m.id,
            name=m.name,
            label=m.label,
            status=m.status,
            error=m.error,
            n_vertices=m.n_vertices,
            file_type=m.file_type,
            size_bytes=m.size_bytes,
            sha256=m.sha256,
            metadata=m.metadata,
            created_at=m.created_at,
            updated_at=m.updated_at,
        )


class ModelsPublic(BaseModel):
    data: list[ModelPublic]
    count: int = Field(description="total matching the filters (not just this page)")


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
        return cls(
            id=j.id,
            kind=j.kind,
            state=j.state,
            model_id=j.model_id,
            attempts=j.attempts,
            error=j.error,
            timings=j.timings,
            payload=j.payload,
            created_at=j.created_at,
            updated_at=j.updated_at,
        )


class JobAccepted(BaseModel):
    job_id: int
    state: str


class SearchHit(BaseModel):
    model_id: int
    name: str
    label: str | None
    distance: float = Field(description="L1 distance between BoF vectors")
    rank: int


class SearchResponse(BaseModel):
    data: list[SearchHit]
    count: int
    vocabulary_id: int
    seconds: dict[str, float] = Field(description="wall time per stage")


class VocabularyRebuild(BaseModel):
    size: int = Field(64, ge=2, le=4096, description="number of geometric words")
    run: str = Field("run5", description="descriptor selection (Table 1 run1..run5)")
    seed: int = 0


class VocabularyPublic(BaseModel):
    id: int | None
    words: int | None
    run: str | None
    trained_on_descriptors: int | None
    created_at: str | None
    indexed_models: int
    versions: int
    metadata: dict[str, Any]


class Health(BaseModel):
    status: str


class Readiness(BaseModel):
    ready: bool
    checks: dict[str, Any]
