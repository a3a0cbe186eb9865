"""Shared fixtures for the service tests: small labelled corpora, settings over temporary data dirs,
a seeded data directory (models ingested, a small vocabulary fitted) that tests copy and mutate."""

from __future__ import annotations

import csv
import fcntl
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from app.config import BudgetSettings, DescribeSettings, Settings
from app.datasets import locate

SHREC = locate.dataset_dir("shrec11-simplified")  # SHAPEBAG_DATASETS (app/datasets/locate.py)
CLASSES = 4
PER_CLASS = 4  # 3 seeded + 1 held out for uploads
TEST_WORDS = 16
TEST_VERTICES = 300  # SHREC meshes (~250 vertices) stay as they are; finer ones are simplified to ~300


def dataset_or_skip(name: str) -> Path:
    """The folder of dataset `name`, or skip the test with a message naming it and how to get it."""
    reason = locate.missing_reason(name)
    if reason is not None:
        pytest.skip(reason)
    return locate.dataset_dir(name)


def needs_dataset(name: str) -> pytest.MarkDecorator:
    """Mark: skip unless dataset `name` is present (the reason says how to get it)."""
    reason = locate.missing_reason(name)
    return pytest.mark.skipif(reason is not None, reason=reason or "")


@dataclass(frozen=True)
class Corpus:
    root: Path
    files: list[tuple[Path, str]]  # (path, label), PER_CLASS per class, grouped by class

    @property
    def seeded(self) -> list[tuple[Path, str]]:
        return [f for i, f in enumerate(self.files) if i % PER_CLASS != PER_CLASS - 1]

    @property
    def held_out(self) -> list[tuple[Path, str]]:
        return [f for i, f in enumerate(self.files) if i % PER_CLASS == PER_CLASS - 1]


def _pick(root: Path) -> list[tuple[Path, str]]:
    by_class: dict[str, list[Path]] = {}
    with open(root / "labels.csv", newline="") as fh:
        for row in csv.DictReader(fh):
            by_class.setdefault(row["class"], []).append(root / row["file"])
    chosen = sorted(by_class)[:CLASSES]
    return [(p, c) for c in chosen for p in sorted(by_class[c])[:PER_CLASS]]


@pytest.fixture(scope="session")
def corpus(tmp_path_factory) -> Corpus:
    """A few SHREC'11 meshes (~250 vertices) when the dataset is present, else a synthetic corpus."""
    if locate.missing_reason("shrec11-simplified") is None:
        return Corpus(SHREC, _pick(SHREC))
    from app.datasets.synthetic import generate

    root = generate(tmp_path_factory.mktemp("synthetic"), classes=CLASSES, per_class=PER_CLASS, seed=0)
    return Corpus(Path(root), _pick(Path(root)))


def make_settings(data_dir: Path, **overrides) -> Settings:
    """Fast settings for tests: a cheap spectrum, one worker, a small vocabulary, no shipped default."""
    base = dict(
        data_dir=data_dir,
        dev_mode=True,
        admin_token="test-token-kkkkkkkkkkkkkkkkkkkkk",
        workers=1,
        search_processes=1,
        describe=DescribeSettings(k=40, m=20, target_vertices=TEST_VERTICES),
        default_vocabulary=None,
        vocabulary_size=TEST_WORDS,
        auto_vocabulary_min_models=10**6,
        poll_interval_s=0.1,
        lease_seconds=20.0,
        warm_up=False,
        describe_timeout_s=60.0,
        # a loaded machine starts pool processes slowly, and a budget's deadline counts that wait: an
        # upload check in a 2-core CI run under other load took over the 30 s default (504). The
        # deadlines themselves are tested with their own short budgets
        check_budget=BudgetSettings(timeout_s=120.0),
        explain_budget=BudgetSettings(queue=4, timeout_s=120.0),
        render_budget=BudgetSettings(timeout_s=120.0),
    )
    base.update(overrides)
    return Settings(**base)


@pytest.fixture
def settings(tmp_path) -> Settings:
    return make_settings(tmp_path / "data")


@pytest.fixture(scope="session")
def seeded_dir(tmp_path_factory, corpus, worker_id) -> Path:
    """A data dir with the seeded corpus ingested and a TEST_WORDS-word vocabulary active, built once per
    test run: under pytest-xdist the first worker builds it in the run's shared temp dir (under a lock) and
    the others wait and reuse it. Read-only: tests copy it (`data_dir`)."""
    if worker_id == "master":  # not under xdist
        return _build_seeded(tmp_path_factory.mktemp("seeded") / "data", corpus)
    shared = tmp_path_factory.getbasetemp().parent  # one per test run, common to its workers
    done = shared / "seeded" / "data"
    with open(shared / "seeded.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not done.is_dir():
            building = shared / f"seeded-{worker_id}"
            _build_seeded(building / "data", corpus)
            done.parent.mkdir(exist_ok=True)
            (building / "data").rename(done)
    return done


def _build_seeded(data_dir: Path, corpus: Corpus) -> Path:
    from app.services import ingestion
    from app.services.context import open_context
    from app.storage import jobs as jobs_repo
    from app.worker.runner import Worker

    ctx = open_context(make_settings(data_dir))
    for path, label in corpus.seeded:
        ingestion.submit(ctx, path.read_bytes(), path.name, name=f"{label}-{path.stem}", label=label)
    worker = Worker(ctx, "seed")
    worker.run_forever(exit_when_idle=True)
    with ctx.db.write() as conn:
        jobs_repo.enqueue(conn, "rebuild_vocabulary", payload={"size": TEST_WORDS})
    worker.run_forever(exit_when_idle=True)
    return data_dir


@pytest.fixture(scope="session")
def worker_id(request) -> str:
    """pytest-xdist's worker name ("gw0", ...), or "master" in a plain run: xdist's fixture of that name,
    also where the plugin is not installed."""
    return getattr(request.config, "workerinput", {}).get("workerid", "master")


@pytest.fixture
def data_dir(seeded_dir, tmp_path) -> Path:
    """A private copy of the seeded data dir, free to mutate."""
    return Path(shutil.copytree(seeded_dir, tmp_path / "data"))


def wait_for(predicate, timeout_s: float = 60.0, interval_s: float = 0.1):
    """Poll `predicate()` until it returns something truthy; fail the test on timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(interval_s)
    pytest.fail(f"condition not met within {timeout_s} s")


def wait_job(client, job_id: int, timeout_s: float = 90.0) -> dict:
    """GET /jobs/{id} until it is done or failed."""

    def finished():
        body = client.get(f"/jobs/{job_id}").json()
        return body if body["state"] in ("done", "failed") else None

    return wait_for(finished, timeout_s)
