"""benchmarks/variants_ingest.py --whole-job: the variant step's share of whole ingest jobs."""

from __future__ import annotations

from pathlib import Path

import trimesh

from app.config import Settings
from app.services.context import open_context
from benchmarks.variants_ingest import run_jobs


def test_whole_jobs_count_every_upload_and_take_the_step_from_the_jobs_timings(tmp_path: Path):
    files = []
    for name, mesh in (("sphere", trimesh.creation.icosphere(2)), ("box", trimesh.creation.box()),
                       ("sphere_copy", trimesh.creation.icosphere(2).apply_scale(25.4))):
        files.append(tmp_path / f"{name}.stl")
        mesh.export(files[-1])
    (tmp_path / "empty.stl").write_bytes(b"solid empty\nendsolid empty\n")
    files.append(tmp_path / "empty.stl")
    row = run_jobs(files, open_context(Settings(data_dir=tmp_path / "data")))
    assert row["models"] == 3 and row["failed"] == 1  # the empty file fails its job, as the worker's would
    assert 0.0 < row["variant step s"] < row["job s"]  # the step ran inside each job and is part of its time
    step, job = row["variant step s"], row["job s"]
    assert row["overhead (step / rest of the job)"] == step / (job - step)
