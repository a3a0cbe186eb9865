"""The seeded data dir: every model described, encoded with the active vocabulary, its own nearest."""

from __future__ import annotations

import numpy as np

from app.services.context import open_context
from app.services.live_index import LiveIndex
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from tests.conftest import TEST_WORDS, make_settings


def test_seeded_models_are_ready_encoded_and_find_themselves(data_dir, corpus):
    ctx = open_context(make_settings(data_dir))
    with ctx.db.read() as conn:
        counts = models_repo.count_by_status(conn)
        active = vocab_repo.active(conn)
        ids, vectors, _ = vocab_repo.vectors(conn, active.id)
    assert counts == {"queued": 0, "ready": len(corpus.seeded), "failed": 0}
    assert active.size == TEST_WORDS and len(ids) == len(corpus.seeded)
    s_bof = active.metadata["fusion"]["bof"]  # the vectors are BoF / s_bof, then the scaled Shape-DNA
    np.testing.assert_allclose(vectors[:, :TEST_WORDS].sum(axis=1) * s_bof, 1.0, atol=1e-5)  # normalised BoF
    live = LiveIndex(ctx)
    live.refresh()
    for mid, vec in zip(ids, vectors, strict=True):
        dist, got, _ = live.search(vec, 1)
        assert got[0] == mid and dist[0] < 1e-6
