"""Parts of multi-object files (issue 33): a file's distinct objects are described and indexed as rows of
the file too, so a query that is one of its objects finds the file, and the hit says which object
matched. Small generated meshes, through httpx (TestClient)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from fastapi.testclient import TestClient

from app.main import create_app
from app.services import ingestion
from app.services.context import open_context
from app.storage import objects as objects_repo
from app.storage import vocabularies as vocab_repo
from app.worker.runner import Worker
from tests.api.test_partial_api import DESCRIBE, _obj, _shapes, describe_and_fit
from tests.conftest import make_settings


def _placed(mesh: trimesh.Trimesh, offset: float, turn: float = 0.0) -> trimesh.Trimesh:
    """A copy turned about z and moved along x, as a slicer lays parts on a plate."""
    out = mesh.copy()
    out.apply_transform(trimesh.transformations.rotation_matrix(turn, [0, 0, 1]))
    out.apply_translation([offset - out.bounds[0][0], 0.0, 0.0])
    return out


def _plate(*meshes: trimesh.Trimesh) -> trimesh.Trimesh:
    """The meshes side by side, 10 % of the widest apart: one file, no two boxes overlapping."""
    gap = 0.1 * max(float(np.ptp(m.vertices[:, 0])) for m in meshes)
    placed, x = [], 0.0
    for i, m in enumerate(meshes):
        p = _placed(m, x, turn=0.7 * i)
        placed.append(p)
        x = float(p.bounds[1][0]) + gap
    return trimesh.util.concatenate(placed)


@pytest.fixture(scope="module")
def plates(tmp_path_factory) -> tuple:
    """The six shapes; a plate of the biped and the torus and one of three quadrupeds stored before the
    vocabulary (its rebuild encodes their object rows); a plate of the snake and the octopus after (its
    ingest does)."""
    data_dir = tmp_path_factory.mktemp("object-rows") / "data"
    ctx = open_context(make_settings(data_dir, describe=DESCRIBE))
    shapes = _shapes()
    ids = {name: ingestion.submit(ctx, _obj(mesh), f"{name}.obj", name=name).model.id
           for name, mesh in shapes.items()}
    for name, parts in (("mixed", ("biped", "torus")), ("copies", ("quadruped",) * 3)):
        plate = _plate(*(shapes[p] for p in parts))
        ids[name] = ingestion.submit(ctx, _obj(plate), f"{name}.obj", name=name).model.id
    describe_and_fit(ctx)
    late = _plate(shapes["snake"], shapes["octopus"])
    ids["late"] = ingestion.submit(ctx, _obj(late), "late.obj", name="late").model.id
    Worker(ctx, "late").run_forever(exit_when_idle=True)
    return data_dir, ids, shapes


def _search(client: TestClient, mesh: trimesh.Trimesh) -> list[dict]:
    r = client.post("/search", files={"file": ("q.obj", _obj(mesh))}, data={"k": "9"})
    assert r.status_code == 200, r.text
    return r.json()["data"]


def test_distinct_objects_get_rows_and_copies_share_one(plates):
    data_dir, ids, _ = plates
    ctx = open_context(make_settings(data_dir, describe=DESCRIBE))
    with ctx.db.read() as conn:
        rows = {name: objects_repo.objects_of(conn, ids[name])
                for name in ("mixed", "copies", "late", "torus")}
        active = vocab_repo.active(conn)
        assert active is not None
        encoded = objects_repo.vectors(conn, active.id)[0]
    assert [r[0] for r in rows["mixed"]] == [1, 2] and [r[1] for r in rows["mixed"]] == [1, 1]
    assert [(part, copies) for part, copies, _ in rows["copies"]] == [(1, 3)]  # one row for three copies
    assert 0.3 < rows["copies"][0][2] < 0.36  # one copy's share of the plate's area
    assert len(rows["late"]) == 2 and rows["torus"] == []  # a single-object file has its whole row only
    # every row has a vector under the active version: the rebuild's and the later ingest's
    held = {(int(m), int(p)) for m, p in zip(*objects_repo.split_row_ids(encoded), strict=True)}
    assert held == {(ids[n], r[0]) for n in ("mixed", "copies", "late") for r in rows[n]}


@pytest.mark.parametrize(("query", "plate"),
                         [("torus", "mixed"), ("quadruped", "copies"), ("octopus", "late")])
def test_one_object_finds_the_file_that_holds_it_and_says_which_object(plates, query, plate):
    data_dir, ids, shapes = plates
    turned = _placed(shapes[query], 5.0, turn=1.1)  # moved and turned: other bytes, the same shape
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        hits = _search(client, turned)
        ranked = [h["model_id"] for h in hits]
        assert ranked[:2] == [ids[query], ids[plate]] or ranked[:2] == [ids[plate], ids[query]]
        on_plate = hits[ranked.index(ids[plate])]
        alone = hits[ranked.index(ids[query])]
        assert on_plate["matched_object"] is not None and alone["matched_object"] is None
        # the variant check then verifies the hit: the query is one object of the plate, moved
        assert (on_plate["relation"], alone["relation"]) == ("part_of", "moved")
        assert on_plate["evidence"]["forward"] == 1.0 and on_plate["evidence"]["reverse"] < 0.7
        # the object is described as a mesh of its own: about the model stored alone (the plate turned
        # it, and a turn moves the canonical resampling a little), far nearer than the third hit
        assert abs(on_plate["distance"] - alone["distance"]) < 0.25 * hits[2]["distance"]
        # the stored model's own neighbours: the plate next
        r = client.get(f"/models/{ids[query]}/similar", params={"k": "3"})
        first = r.json()["data"][0]
        assert (first["model_id"], first["matched_object"] is not None) == (ids[plate], True)


def test_a_plates_whole_shape_still_answers_for_itself(plates):
    """The whole row stays: the plate's own file finds the plate first, at distance 0, as its whole."""
    data_dir, ids, shapes = plates
    with TestClient(create_app(make_settings(data_dir, describe=DESCRIBE))) as client:
        hits = _search(client, _plate(shapes["biped"], shapes["torus"]))
        assert hits[0]["model_id"] == ids["mixed"] and hits[0]["matched_object"] is None
        assert hits[0]["distance"] < 1e-3


def test_deleting_a_plate_takes_its_object_rows_and_their_files(plates, tmp_path):
    data_dir, ids, shapes = plates
    settings = make_settings(data_dir, describe=DESCRIBE)
    ctx = open_context(settings)
    files = ctx.blobs.object_description_paths(ids["late"])
    assert len(files) == 2
    with TestClient(create_app(settings)) as client:
        admin = {"X-Admin-Token": settings.admin_token}  # no SHAPEBAG_API_TOKEN: deletes need the admin's
        assert client.delete(f"/models/{ids['late']}", headers=admin).status_code == 204
        hits = _search(client, shapes["octopus"])
        assert ids["late"] not in [h["model_id"] for h in hits]
        assert client.get("/readyz").status_code == 200
    assert not any(p.exists() for p in files)
    with ctx.db.read() as conn:
        assert objects_repo.objects_of(conn, ids["late"]) == []
        left = conn.execute("SELECT COUNT(*) FROM object_bof WHERE model_id = ?", (ids["late"],)).fetchone()
        assert left[0] == 0
