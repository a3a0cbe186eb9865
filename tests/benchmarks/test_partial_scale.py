"""benchmarks.partial_scale: synthetic models are stored where, and as, the service's search reads them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.core.partial import LocalSignature
from app.core.pipeline import ShapeDescription
from app.datasets.folder import LabelledFile
from app.services import partial as partial_mod
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from benchmarks import partial_scale


def _description(rng: np.random.Generator) -> ShapeDescription:
    local = LocalSignature(slopes=rng.normal(-0.6, 0.2, (40, 16)).astype(np.float32),
                           area=np.full(40, 1 / 40, np.float32), valid=np.full(40, 16, np.int16), rim=0.0,
                           vertex=np.arange(40, dtype=np.int32),
                           level=rng.normal(-2.5, 0.3, 40).astype(np.float32),
                           surface=rng.normal(0.0, 0.3, (60, 3)).astype(np.float16))
    return ShapeDescription(hks=np.zeros((1, 1), np.float32), weights=np.ones(1, np.float32),
                            keypoints=np.zeros(1, bool), eigenvalues=np.zeros(2), input_vertices=500,
                            local=local, input_noise=0.25)


def test_synthetic_models_are_jittered_copies_the_search_path_reads(tmp_path, monkeypatch):
    rng = np.random.default_rng(0)
    descs = [_description(rng) for _ in range(3)]
    rows = [LabelledFile(Path(f"/x/m{i}.off"), f"class{i}") for i in range(3)]
    ctx = partial_scale.open_service(tmp_path / "data")
    with ctx.db.read() as conn:
        vid = vocab_repo.active(conn).id  # the shipped vocabulary, registered as the server does
    vectors = {id(d): np.full(5, i + 1.0, np.float32) for i, d in enumerate(descs)}
    monkeypatch.setattr(partial_scale, "_encoder", lambda ctx: (vid, lambda d: vectors[id(d)]))
    monkeypatch.setattr(partial_scale, "BATCH", 4)  # several transactions
    partial_scale.store_synthetic(ctx, rows, descs, 10)
    with ctx.db.read() as conn:
        ids, stored, _ = vocab_repo.vectors(conn, vid)
        records = models_repo.get_many(conn, [int(i) for i in ids])
    assert len(ids) == 10 and all(r.status == "ready" for r in records.values())
    for mid, vector in zip(ids, stored, strict=True):
        record = records[int(mid)]
        source = int(record.name.rsplit("-of-m", 1)[1])
        assert record.label == f"class{source}"
        # (1 - w) of its source's vector and w <= 0.3 of another's, each entry jittered by exp(N(0, 0.1²))
        assert 0.8 < vector.mean() < 3.6 and np.ptp(vector) > 0
        sig = partial_mod.local_of(ctx, int(mid))  # what the coarse pass and the scoring read
        src = descs[source].local
        assert sig is not None and sig.slopes.dtype == np.float32
        np.testing.assert_array_equal(sig.valid, src.valid)
        np.testing.assert_array_equal(sig.vertex, src.vertex)
        noise = sig.slopes - src.slopes
        assert np.std(noise) == pytest.approx(partial_scale.SLOPE_JITTER, rel=0.2)
        assert sig.level is not None and src.level is not None  # the level is read as the service reads it
        assert np.std(sig.level - src.level) == pytest.approx(partial_scale.SLOPE_JITTER, rel=0.35)
        assert partial_mod.noise_of(ctx, int(mid)) == pytest.approx(0.25)
        # its source's surface: the fits screen and fit a copy as they do a real model
        assert sig.surface is not None
        np.testing.assert_array_equal(sig.surface, src.surface)
