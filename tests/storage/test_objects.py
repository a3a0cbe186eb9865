"""Object rows' storage (app/storage/objects.py), on SQLite and PostgreSQL (tests/storage/conftest.py):
rows and vectors round-trip, a version's missing vectors are found, and both go with their model."""

from __future__ import annotations

import time

import numpy as np

from app.storage import models as models_repo
from app.storage import objects as objects_repo
from app.storage import vocabularies as vocab_repo


def _ready_model(conn) -> int:
    mid = models_repo.insert(conn, name="plate", label=None, metadata={}, sha256=str(time.time_ns()),
                             file_type="obj", size_bytes=1)
    models_repo.set_ready(conn, mid, 10)
    return mid


def test_object_rows_round_trip_and_go_with_their_model(db):
    with db.write() as conn:
        vid = vocab_repo.insert(conn, path="v", trained_on=1, size=2, run="run5", metadata={})
        plate, single = _ready_model(conn), _ready_model(conn)
        objects_repo.put_objects(conn, plate, [(1, 3, 0.25), (2, 1, 0.5)])
        objects_repo.put_vector(conn, plate, 1, vid, np.array([1.0, 2.0], np.float32))
    with db.read() as conn:
        assert objects_repo.objects_of(conn, plate) == [(1, 3, 0.25), (2, 1, 0.5)]
        assert objects_repo.objects_of(conn, single) == []
        assert objects_repo.ready_parts(conn) == [(plate, 1), (plate, 2)]
        assert objects_repo.parts_without_vector(conn, vid) == [(plate, 2)]
        ids, vectors, seq = objects_repo.vectors(conn, vid)
    assert ids.tolist() == [objects_repo.row_id(plate, 1)] and vectors.tolist() == [[1.0, 2.0]] and seq > 0
    models, parts = objects_repo.split_row_ids(ids)
    assert (models.tolist(), parts.tolist()) == ([plate], [1])
    with db.write() as conn:  # a replaced vector gets a new sequence number: pollers see it
        objects_repo.put_vector(conn, plate, 1, vid, np.array([3.0, 4.0], np.float32))
    with db.read() as conn:
        again, vectors, later = objects_repo.vectors(conn, vid, seq)
    assert again.tolist() == ids.tolist() and vectors.tolist() == [[3.0, 4.0]] and later > seq
    with db.write() as conn:
        models_repo.delete(conn, plate)
    with db.read() as conn:
        assert objects_repo.objects_of(conn, plate) == [] and objects_repo.ready_parts(conn) == []
        assert len(objects_repo.vectors(conn, vid)[0]) == 0
