"""ApproxL1Index past its training threshold (the shared suite covers it below, where it is exact)."""

from __future__ import annotations

import numpy as np
import pytest

from app.index import IndexFileError
from app.index.approximate import ApproxL1Index, nlist_for

DIM = 64


def _clustered(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """BoF-like vectors around 30 'classes' (rows sum to 1), ids scattered."""
    rng = np.random.default_rng(seed)
    centres = rng.dirichlet(np.full(DIM, 0.3), size=30)
    x = 0.8 * centres[rng.integers(0, 30, n)] + 0.2 * rng.dirichlet(np.full(DIM, 0.3), size=n)
    return rng.choice(10**7, size=n, replace=False).astype(np.int64), x.astype(np.float32)


def _exact(ids, base, queries, k):
    dist = np.abs(queries[:, None, :].astype(np.float64) - base[None]).sum(axis=2)
    return ids[np.argsort(dist, axis=1)[:, :k]]


@pytest.fixture
def trained() -> tuple[ApproxL1Index, np.ndarray, np.ndarray]:
    ids, base = _clustered(4000)
    index = ApproxL1Index(DIM, train_at=1000)
    index.add(ids[:999], base[:999])
    assert not index.approximate
    index.add(ids[999:], base[999:])
    index.wait_for_training()
    assert index.approximate and index.count == 4000 and not index.training
    return index, ids, base


def test_crossing_the_threshold_trains_an_ivf_that_keeps_every_vector(trained):
    index, ids, _ = trained
    assert index._index.nlist == nlist_for(4000)
    np.testing.assert_array_equal(index.ids(), np.sort(ids))


def test_scanning_every_cell_is_exact_and_default_recall_is_high(trained):
    index, ids, base = trained
    rng = np.random.default_rng(1)
    noise = rng.normal(0, 1e-3, (50, DIM)).astype(np.float32)
    queries = base[rng.choice(len(base), 50, replace=False)] + noise
    want = _exact(ids, base, queries, 10)
    _, got = index.search(queries, 10)
    recall = np.mean([len(set(a) & set(b)) / 10 for a, b in zip(got, want, strict=True)])
    assert recall >= 0.9
    index.nprobe = index._index.nlist
    dist, got = index.search(queries, 10)
    np.testing.assert_array_equal(got, want)
    assert np.all(np.diff(dist, axis=1) >= 0)


def test_remove_replace_and_filter_after_training(trained):
    index, ids, base = trained
    assert index.remove(ids[:10]) == 10 and index.remove(ids[:10]) == 0
    assert index.count == 3990 and not np.isin(ids[:10], index.ids()).any()
    index.nprobe = index._index.nlist
    _, got = index.search(base[:10], 1)
    assert not np.isin(got, ids[:10]).any()
    index.add(ids[20:21], base[:1])  # replaces id 20's vector
    dist, got = index.search(base[:1], 1)
    assert index.count == 3990 and got[0, 0] == ids[20] and dist[0, 0] == pytest.approx(0.0, abs=1e-6)
    allowed = ids[100:400:3]
    _, got = index.search(base[:5], 5, allowed_ids=allowed)
    assert np.isin(got, allowed).all()


def test_trained_index_round_trips(trained, tmp_path):
    index, _, base = trained
    path = tmp_path / "index-ivf.faiss"
    index.save(path)
    loaded = ApproxL1Index.load(path)
    assert loaded.approximate and loaded.count == index.count
    np.testing.assert_array_equal(loaded.ids(), index.ids())
    for a, b in zip(loaded.search(base[:20], 5), index.search(base[:20], 5), strict=True):
        np.testing.assert_array_equal(a, b)
    assert loaded.remove(loaded.ids()[:3]) == 3


def test_training_runs_to_the_side_and_replays_what_happened_meanwhile(monkeypatch):
    import threading

    from app.index import approximate

    release = threading.Event()
    real_build = approximate._build_ivf

    def slow_build(*args):
        release.wait(30)  # hold the build until the adds and removes below have happened
        return real_build(*args)

    monkeypatch.setattr(approximate, "_build_ivf", slow_build)
    ids, base = _clustered(3000)
    index = ApproxL1Index(DIM, train_at=1000)
    index.add(ids[:2000], base[:2000])  # crosses train_at: the build starts and waits
    assert index.training and not index.approximate
    index.add(ids[2000:], base[2000:])  # served and logged while the build runs
    assert index.remove(ids[:100]) == 100
    index.add(ids[200:201], base[0:1])  # a replacement, logged too
    _, got = index.search(base[500:505], 1)  # the flat index answers meanwhile, exactly
    np.testing.assert_array_equal(got[:, 0], ids[500:505])
    release.set()
    index.wait_for_training()
    assert index.approximate and not index.training and index.count == 2900
    np.testing.assert_array_equal(index.ids(), np.sort(ids[100:]))
    index.nprobe = index._index.nlist
    keep, vectors = ids[100:], base[100:].copy()
    vectors[100] = base[0]  # id ids[200] now holds base[0]
    _, got = index.search(base[:50], 10)
    np.testing.assert_array_equal(got, _exact(keep, vectors, base[:50], 10))


def test_a_failed_build_is_reported_and_the_index_keeps_serving(monkeypatch):
    from app.index import approximate

    def broken(*args):
        raise RuntimeError("k-means exploded")

    monkeypatch.setattr(approximate, "_build_ivf", broken)
    ids, base = _clustered(1200)
    index = ApproxL1Index(DIM, train_at=1000)
    index.add(ids, base)
    with pytest.raises(RuntimeError, match="exploded"):
        index.wait_for_training()
    assert not index.approximate and index.count == 1200
    _, got = index.search(base[:3], 1)
    np.testing.assert_array_equal(got[:, 0], ids[:3])


def test_load_refuses_an_index_of_another_metric(tmp_path):
    import faiss

    path = tmp_path / "l2.faiss"
    faiss.write_index(faiss.IndexIDMap2(faiss.IndexFlatL2(DIM)), str(path))
    with pytest.raises(IndexFileError):
        ApproxL1Index.load(path)
