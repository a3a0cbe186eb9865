"""Relations for a query that is not stored: verification in the pool process, within its budget."""

from __future__ import annotations

import asyncio
import time

import numpy as np

from app.services import variant_query
from tests.variant_meshes import hull_trimesh


def _hull(tmp_path, name: str, scale: float = 1.0, seed: int = 5) -> tuple[bytes, str]:
    data = hull_trimesh(seed, scale=scale).export(file_type="stl")
    (tmp_path / name).write_bytes(data)
    return data, str(tmp_path / name)


def test_relate_query_keeps_the_variants_and_respects_its_budget(tmp_path) -> None:
    query, _ = _hull(tmp_path, "q.stl")
    _, inches = _hull(tmp_path, "inches.stl", scale=1 / 25.4)
    _, other = _hull(tmp_path, "other.stl", seed=9)
    stored = [(7, inches, "stl"), (8, other, "stl"), (9, str(tmp_path / "gone.stl"), "stl")]
    found = variant_query.relate_query(query, "stl", 10_000, stored, budget_s=60.0)
    assert list(found) == [7] and found[7]["relation"] == "rescaled"
    assert abs(found[7]["scale"] - 1 / 25.4) < 1e-9
    assert variant_query.relate_query(query, "stl", 10_000, stored, budget_s=0.0) == {}  # no time: none
    fp = variant_query.query_fingerprints(query, "stl", 10_000)
    assert fp.shape == (1, 17) and fp.dtype == np.float32


def test_no_time_left_no_step(tmp_path) -> None:
    """Past the deadline nothing is started (not even the pool is asked)."""
    late = time.monotonic() + 0.1
    assert asyncio.run(variant_query.relations(None, None, b"", "stl", [1, 2], late)) == {}  # type: ignore[arg-type]
    assert asyncio.run(variant_query.relations(None, None, b"", "stl", [], late + 60)) == {}  # type: ignore[arg-type]
