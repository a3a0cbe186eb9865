"""One suite for every ShapeIndex backend: L1 search equals brute force, and state round-trips."""

from __future__ import annotations

import numpy as np
import pytest

from app.index import BACKENDS, IndexFileError, ShapeIndex, new_index

DIM = 64


@pytest.fixture(params=sorted(BACKENDS))
def backend(request) -> str:
    return request.param


def _data(n: int = 200, q: int = 7, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    base = rng.dirichlet(np.ones(DIM), size=n).astype(np.float32)  # BoF-like: rows sum to 1
    ids = rng.choice(10_000, size=n, replace=False).astype(np.int64)
    return ids, base, rng.dirichlet(np.ones(DIM), size=q).astype(np.float32)


def _brute(ids, base, queries, k, allowed=None):
    mask = np.ones(len(ids), bool) if allowed is None else np.isin(ids, allowed)
    dist = np.abs(queries[:, None, :].astype(np.float64) - base[mask][None]).sum(axis=2)
    order = np.argsort(dist, axis=1)[:, :k]
    return np.take_along_axis(dist, order, axis=1), ids[mask][order]


def test_satisfies_protocol(backend):
    assert isinstance(new_index(backend, DIM), ShapeIndex)


def test_l1_search_equals_brute_force(backend):
    ids, base, queries = _data()
    index = new_index(backend, DIM)
    index.add(ids, base)
    dist, got = index.search(queries, 10)
    want_d, want_i = _brute(ids, base, queries, 10)
    assert got.shape == (7, 10) and dist.dtype == np.float32
    np.testing.assert_array_equal(got, want_i)
    np.testing.assert_allclose(dist, want_d, rtol=1e-5, atol=1e-6)


def test_label_filter_restricts_to_allowed_ids(backend):
    ids, base, queries = _data()
    allowed = ids[::5]
    index = new_index(backend, DIM)
    index.add(ids, base)
    dist, got = index.search(queries, 5, allowed_ids=allowed)
    assert np.isin(got, allowed).all()
    np.testing.assert_array_equal(got, _brute(ids, base, queries, 5, allowed)[1])


def test_fewer_candidates_than_k_pads_with_minus_one(backend):
    ids, base, queries = _data(n=3)
    index = new_index(backend, DIM)
    index.add(ids, base)
    dist, got = index.search(queries[:1], 5)
    assert (got[0, :3] >= 0).all() and (got[0, 3:] == -1).all() and np.isinf(dist[0, 3:]).all()
    _, none = index.search(queries[:1], 2, allowed_ids=np.array([], np.int64))
    assert (none == -1).all()


def test_add_remove_and_replace(backend):
    ids, base, queries = _data(n=50)
    index = new_index(backend, DIM)
    index.add(ids, base)
    assert index.count == 50
    assert index.remove(ids[:10]) == 10
    assert index.remove(ids[:10]) == 0
    assert index.count == 40
    np.testing.assert_array_equal(index.ids(), np.sort(ids[10:]))
    _, got = index.search(base[:10], 1)
    assert not np.isin(got, ids[:10]).any()
    index.add(ids[20:21], queries[:1])  # re-adding an id replaces its vector
    assert index.count == 40
    dist, got = index.search(queries[:1], 1)
    assert got[0, 0] == ids[20] and dist[0, 0] == pytest.approx(0.0, abs=1e-6)


def test_save_load_round_trip(backend, tmp_path):
    ids, base, queries = _data()
    index = new_index(backend, DIM)
    index.add(ids, base)
    index.remove(ids[:3])
    path = tmp_path / "v1" / "index.bin"
    path.parent.mkdir()
    index.save(path)
    loaded = type(index).load(path)
    assert loaded.count == index.count and loaded.dim == DIM
    np.testing.assert_array_equal(loaded.ids(), index.ids())
    for a, b in zip(loaded.search(queries, 8), index.search(queries, 8), strict=True):
        np.testing.assert_array_equal(a, b)


def test_load_refuses_missing_or_corrupt_files(backend, tmp_path):
    cls = type(new_index(backend, DIM))
    with pytest.raises(IndexFileError):
        cls.load(tmp_path / "absent")
    bad = tmp_path / "bad"
    bad.write_bytes(b"not an index at all")
    with pytest.raises(IndexFileError):
        cls.load(bad)


def test_wrong_dimension_is_refused(backend):
    index = new_index(backend, DIM)
    with pytest.raises(ValueError):
        index.add(np.array([1]), np.zeros((1, DIM + 1), np.float32))
