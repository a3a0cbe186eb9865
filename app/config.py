"""One settings object, read from SHAPEBAG_* environment variables; built in create_app(), never at import."""

from __future__ import annotations

import ipaddress
import os
from importlib import resources
from importlib.util import find_spec
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, Field, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from app.core.pipeline import DescribeParams
from app.core.resolution import SUBDIVISIONS
from app.core.smoothing import WEIGHTS
from app.core.vocabulary import EncodeParams

DEFAULT_ADMIN_TOKEN = "change-me"
MIN_TOKEN_CHARS = 32  # e.g. python3 -c 'import secrets; print(secrets.token_urlsafe(24))'
LOOPBACK_NAMES = ("localhost",)
# package data ([tool.setuptools.package-data]): one path for editable, wheel and container installs
SHIPPED_VOCABULARY = Path(str(resources.files("app") / "data" / "vocabulary" / "default"))


class DescribeSettings(BaseModel):
    """Per-shape computation (SHAPEBAG_DESCRIBE__K=300 ...)."""

    k: int = Field(default=DescribeParams.k, ge=2)
    m: int = Field(default=DescribeParams.m, ge=4)
    target_vertices: int = Field(default=DescribeParams.target_vertices, ge=0)
    smoothing: int = Field(default=DescribeParams.smoothing, ge=0)
    antialias: float = Field(default=DescribeParams.antialias, ge=0.0)  # canonical edge lengths; 0: none
    antialias_start: float = Field(default=DescribeParams.antialias_start, ge=0.0)  # ratio: none up to it
    antialias_full: float = Field(default=DescribeParams.antialias_full, ge=0.0)  # ratio: full from it
    smoothing_weights: str = DescribeParams.smoothing_weights  # one of app.core.smoothing.WEIGHTS
    time_range: Literal["spectrum", "weyl"] = DescribeParams.time_range  # type: ignore[assignment]
    laplacian: Literal["cotangent", "intrinsic"] = DescribeParams.laplacian  # type: ignore[assignment]
    remesh: bool = DescribeParams.remesh
    fill_holes: float = Field(default=DescribeParams.fill_holes, ge=0.0, lt=1.0)
    subdivision: str = DescribeParams.subdivision
    solver: str = "auto"

    @field_validator("subdivision")
    @classmethod
    def _known_subdivision(cls, value: str) -> str:
        if value not in SUBDIVISIONS:
            raise ValueError(f"must be one of {', '.join(SUBDIVISIONS)}")
        return value

    @field_validator("remesh")
    @classmethod
    def _remesher_installed(cls, value: bool) -> bool:  # an extra: say how to get it before any upload
        if value and find_spec("gpytoolbox") is None:
            raise ValueError("remeshing needs gpytoolbox: pip install 'shapebag[remesh]'")
        return value

    @field_validator("smoothing_weights")
    @classmethod
    def _known_smoothing_weights(cls, value: str) -> str:  # the core's list, not a copy of it
        if value not in WEIGHTS:
            raise ValueError(f"must be one of {', '.join(WEIGHTS)}")
        return value

    @model_validator(mode="after")
    def _ramp_in_order(self) -> DescribeSettings:
        if self.antialias_start > self.antialias_full:
            raise ValueError(f"antialias_start ({self.antialias_start}) must not exceed antialias_full "
                             f"({self.antialias_full})")
        return self

    def params(self) -> DescribeParams:
        return DescribeParams(**self.model_dump())


class EncodeSettings(BaseModel):
    """How a description becomes a BoF vector (SHAPEBAG_ENCODE__MODE=soft ...)."""

    mode: Literal["soft", "hard"] = "soft"  # EncodeParams.mode (tests/test_config.py checks they agree)
    sigma_scale: float = Field(default=EncodeParams.sigma_scale, gt=0, allow_inf_nan=False)
    keypoints_only: bool = False
    area_weighted: bool = EncodeParams.area_weighted
    fusion: bool = True  # append the scaled Shape-DNA when the vocabulary has fusion scales (app.core.fusion)

    def params(self) -> EncodeParams:
        return EncodeParams(**self.model_dump())  # normalize keeps its default (True)


class BudgetSettings(BaseModel):
    """One kind of costly work's budget (docs/reliability.md, "Budgets"): SHAPEBAG_EXPLAIN_BUDGET__QUEUE=2."""

    concurrency: int = Field(default=1, ge=1)  # requests of this kind running at once
    queue: int = Field(default=8, ge=0)  # waiting beyond them: 503 busy
    timeout_s: float = Field(default=30.0, gt=0)  # deadline, waiting included: 504, process replaced


class StorageSettings(BaseModel):
    """Room on the data directory (SHAPEBAG_STORAGE__MIN_FREE_MB=1024 ...): under the floor, or past the
    quota, writes answer 507 before the disk (and SQLite) fills; reads and DELETE keep working."""

    min_free_mb: int = Field(default=512, ge=0)  # free space the filesystem keeps; 0: no floor
    quota_mb: int = Field(default=0, ge=0)  # bytes under data_dir (meshes, descriptions, database); 0: none
    measure_interval_s: float = Field(default=10.0, ge=0)  # how stale the quota's count of bytes may be


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="SHAPEBAG_", env_nested_delimiter="__", extra="ignore")

    data_dir: Path = Path("data")  # the repository's data/ when run from a checkout (data/README.md)
    database_url: str = ""  # empty: SQLite in data_dir; postgresql://...: shared state there (docs/deploy.md)
    # filesystem: meshes and descriptions under data_dir; database: in the database, data_dir caches them
    blob_backend: Literal["filesystem", "database"] = "filesystem"
    host: str = "127.0.0.1"
    port: int = 8000
    workers: int = Field(default_factory=lambda: os.cpu_count() or 1, ge=0)  # embedded ingestion processes
    pool_processes: int = Field(default=3, ge=1)  # shared by the budgets below, one request each
    search_processes: int = Field(default=2, ge=1)  # query descriptions at once (one process kept for them)
    search_queue: int = Field(default=8, ge=0)  # query descriptions waiting before 503
    check_budget: BudgetSettings = Field(default_factory=lambda: BudgetSettings(timeout_s=30.0))
    explain_budget: BudgetSettings = Field(default_factory=lambda: BudgetSettings(queue=4, timeout_s=60.0))
    render_budget: BudgetSettings = Field(default_factory=lambda: BudgetSettings(timeout_s=20.0))
    # pieces matched at once in the API process (services/piece_budget.py); timeout_s: the longest wait
    piece_budget: BudgetSettings = Field(
        default_factory=lambda: BudgetSettings(concurrency=2, timeout_s=10.0))
    client_requests: int = Field(default=8, ge=1)  # costly requests one client has in flight; more: 429
    ingest_timeout_s: float = Field(default=120.0, gt=0)  # wall clock of one ingest job; then failed
    worker_nice: int = Field(default=10, ge=0, le=19)  # ingestion yields the cores to searches
    worker_memory_mb: int = Field(default=4096, ge=0)  # RLIMIT_AS of worker and pool processes; 0: none
    upload_timeout_s: float = Field(default=30.0, gt=0)  # no body bytes for this long: 408
    # a connection's request headers complete within this, or it is closed (shapebag serve)
    header_timeout_s: float = Field(default=15.0, gt=0)
    # the reverse proxy's addresses (comma-separated, or "*") whose X-Forwarded-For names the client:
    # the per-client bounds then see each user, not the proxy. Empty: the connection's own address
    forwarded_allow_ips: str = ""
    # past upload_timeout_s, a body arriving slower than this on average is given up (408); 0: no floor
    upload_min_rate_kib_s: float = Field(default=8.0, ge=0)
    max_concurrent_uploads: int = Field(default=16, ge=1)  # request bodies read at once; more: 503
    client_uploads: int = Field(default=4, ge=1)  # of those, one client's at once; more: 429
    warm_up: bool = True  # start the query pool at startup, so the first search does not pay for it
    admin_token: str = DEFAULT_ADMIN_TOKEN
    api_token: str = ""  # set: POST /models and DELETE /models/{id} need it (or the admin token)
    dev_mode: bool = False
    log_level: str = "INFO"  # of the worker processes
    cors_origins: list[str] = []  # closed by default
    max_upload_bytes: int = 50 * 1024 * 1024
    max_vertices: int = 2_000_000
    describe_timeout_s: float = 60.0
    queue_limit: int = 10_000  # queued ingest jobs beyond which uploads get 503
    lease_seconds: float = 120.0
    max_attempts: int = 3
    poll_interval_s: float = 0.5  # how often the API process looks for newly ready models
    index_save_interval_s: float = 30.0
    index_backend: str = "faiss"  # faiss | numpy
    # fused vectors: each whole-shape query re-ranks the index's candidates by a query-adaptive fusion
    # (services/fusion_rerank); a hit's distance stays the index's L1, the re-rank's comes beside it
    fusion_rerank: bool = True
    # distinct objects of a multi-object file (a print plate, an assembly) described and indexed as rows
    # of the file too, so that one of its objects finds it (app.core.object_rows); 0: whole rows only
    object_rows: int = Field(default=8, ge=0, le=32)
    vocabulary_size: int = 64
    vocabulary_run: str = "run5"
    auto_vocabulary_min_models: int = 16  # with no vocabulary, fit one once this many models are ready
    # refit the vocabulary on the collection at this many ready models, and again at each doubling since
    # the last fit (services/refit.py); 0: never (measured: it does not help at the defaults, docs/results.md)
    vocabulary_refit_at: int = Field(default=0, ge=0)
    default_vocabulary: Path | None = SHIPPED_VOCABULARY
    describe: DescribeSettings = Field(default_factory=DescribeSettings)
    encode: EncodeSettings = Field(default_factory=EncodeSettings)
    storage: StorageSettings = Field(default_factory=StorageSettings)

    @field_validator("default_vocabulary", mode="before")
    @classmethod
    def _empty_is_none(cls, value: object) -> object:
        return None if value == "" else value  # SHAPEBAG_DEFAULT_VOCABULARY= disables the shipped one

    def check_secure(self) -> None:
        """Refuse to start with a guessable token or an open dev mode on the network.

        Outside dev mode the admin token must be set, not the default, and long; a set API token must be
        long; dev mode (the default admin token allowed) only binds a loopback address."""
        if not self.dev_mode and (not self.admin_token or self.admin_token == DEFAULT_ADMIN_TOKEN):
            raise ValueError(
                "SHAPEBAG_ADMIN_TOKEN is unset or the default: set a secret token, or SHAPEBAG_DEV_MODE=1"
            )
        tokens = {"SHAPEBAG_API_TOKEN": self.api_token}
        if self.admin_token != DEFAULT_ADMIN_TOKEN:
            tokens["SHAPEBAG_ADMIN_TOKEN"] = self.admin_token
        for name, token in tokens.items():
            if token and len(token) < MIN_TOKEN_CHARS:
                raise ValueError(
                    f"{name} is {len(token)} characters long: use at least {MIN_TOKEN_CHARS} (for example"
                    " python3 -c 'import secrets; print(secrets.token_urlsafe(24))')"
                )
        if self.dev_mode and not is_loopback(self.host):
            raise ValueError(
                f"SHAPEBAG_DEV_MODE allows the default admin token, so it only serves a loopback address"
                f" (127.0.0.1, ::1, localhost), not {self.host!r}: set SHAPEBAG_ADMIN_TOKEN and turn dev"
                " mode off to serve the network"
            )


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 or localhost; False for 0.0.0.0, '' (every address) and any other name."""
    if host.lower() in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False
