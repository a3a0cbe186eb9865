"""The container deployment, for real: build, upload through the published port, worker ingests, search,
restart with the volume kept, scale the worker to 2, then `down -v`.

Run alone:  .venv/bin/pytest -q -m docker tests/deploy   (a few minutes when the engine and cache are warm)
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import pytest

from app.datasets import locate
from tests.deploy.conftest import wait_for

if TYPE_CHECKING:  # conftest is pytest's to import; at runtime the fixture hands the object over
    from tests.deploy.conftest import Compose

pytestmark = [pytest.mark.docker, pytest.mark.slow]

DATASET = locate.dataset_dir("shrec11-simplified")
SHIPPED = Path(__file__).resolve().parents[2] / "app" / "data" / "vocabulary" / "default" / "vocabulary.json"
WAIT_S = 240  # --wait for build + healthy; each bounded poll below has its own limit


def meshes(n: int) -> list[tuple[str, str, bytes]]:
    """(file name, label, OBJ bytes) of n shapes from n different classes of the shared dataset, or, where the
    dataset is absent, n trimesh primitives (the test is about the deployment, not retrieval quality)."""
    labels = DATASET / "labels.csv"
    if labels.is_file():
        out: list[tuple[str, str, bytes]] = []
        seen: set[str] = set()
        with labels.open(newline="") as fh:
            for row in csv.DictReader(fh):
                if row["class"] not in seen and len(out) < n:
                    seen.add(row["class"])
                    out.append((Path(row["file"]).name, row["class"], (DATASET / row["file"]).read_bytes()))
        return out
    import trimesh

    shapes = [
        trimesh.creation.icosphere(3),
        trimesh.creation.capsule(2.0, 0.5),
        trimesh.creation.annulus(0.5, 1.0, 1.0),
        trimesh.creation.cylinder(0.6, 2.5, sections=40),
    ]
    return [
        (f"prim{i}.obj", f"prim{i}", m.export(file_type="obj").encode()) for i, m in enumerate(shapes[:n])
    ]


def upload(client: httpx.Client, name: str, label: str, data: bytes) -> dict[str, Any]:
    r = client.post(
        "/models",
        files={"file": (name, data, "application/octet-stream")},
        data={"name": name, "label": label},
    )
    assert r.status_code == 202, f"upload {name}: {r.status_code} {r.text}"
    body = r.json()
    assert body["job_id"] is not None, body
    return body


def job_done(client: httpx.Client, job_id: int) -> Callable[[], bool]:
    def probe() -> bool:
        job = client.get(f"/jobs/{job_id}").json()
        assert job["state"] != "failed", f"job {job_id} failed: {job.get('error')}"
        return job["state"] == "done"

    return probe


def readiness(client: httpx.Client) -> dict[str, Any]:
    return client.get("/readyz").json()


def ensure_vocabulary(client: httpx.Client, compose: Compose, indexed: int) -> None:
    """The shipped vocabulary is normally active; where a checkout has none, fit one on the uploads."""
    admin = {"X-Admin-Token": compose.env["SHAPEBAG_ADMIN_TOKEN"]}
    active = client.get("/admin/vocabulary", headers=admin).json()["id"]
    if SHIPPED.is_file():  # the image carries it (package data): it must be the active one
        assert active is not None, (
            f"{SHIPPED.parent} is in the repo but the api has no vocabulary\n{compose.logs()}"
        )
    elif active is None:
        r = client.post("/admin/vocabulary/rebuild", headers=admin, json={"size": 16})
        assert r.status_code == 202, r.text
        wait_for("the vocabulary fit", job_done(client, r.json()["job_id"]), 180, compose)
    wait_for(
        f"{indexed} models in the api's index",
        lambda: readiness(client)["checks"].get("indexed_models", 0) >= indexed,
        60,
        compose,
    )


def assert_finds_itself(
    client: httpx.Client, name: str, data: bytes, model_id: int, compose: Compose
) -> None:
    r = client.post("/search", files={"file": (name, data, "application/octet-stream")}, data={"k": "3"})
    assert r.status_code == 200, f"search {name}: {r.status_code} {r.text}\n{compose.logs()}"
    hits = r.json()["data"]
    assert hits, f"search {name}: no hits"
    assert hits[0]["model_id"] == model_id, f"search {name}: expected model {model_id} first, got {hits}"
    assert hits[0]["distance"] == pytest.approx(0.0, abs=1e-5), hits[0]


def service_states(compose: Compose, service: str) -> list[dict[str, Any]]:
    out = compose.run("ps", "--format", "json", service).stdout.strip()
    if not out:
        return []
    # compose prints one JSON object per line (v2.21+) or one array (older)
    rows = json.loads(out) if out.startswith("[") else [json.loads(line) for line in out.splitlines()]
    return rows


def test_compose_stack_end_to_end(stack: Compose) -> None:
    t0 = time.monotonic()
    stack.run("up", "-d", "--build", "--wait", "--wait-timeout", str(WAIT_S), timeout=WAIT_S + 900)
    print(f"up --build --wait: {time.monotonic() - t0:.1f} s")
    shapes = meshes(4)
    assert len(shapes) == 4, shapes

    with httpx.Client(base_url=stack.base_url, timeout=60) as client:
        assert client.get("/healthz").status_code == 200

        # upload through the published port; the worker service (the api runs none) ingests them
        t = time.monotonic()
        accepted = {name: upload(client, name, label, data) for name, label, data in shapes[:3]}
        for name, body in accepted.items():
            wait_for(f"the worker to ingest {name}", job_done(client, body["job_id"]), 180, stack)
        print(f"3 uploads ingested by the worker in {time.monotonic() - t:.1f} s")
        ensure_vocabulary(client, stack, indexed=3)
        for name, _, data in shapes[:3]:
            assert_finds_itself(client, name, data, accepted[name]["model_id"], stack)
        # the web page's files are package data: they must have made it into the installed wheel
        page = client.get("/")
        assert page.status_code == 200 and "<html" in page.text.lower(), page.text[:200]
        thumb = client.get(f"/models/{accepted[shapes[0][0]]['model_id']}/thumbnail.png")
        assert thumb.status_code == 200 and thumb.content.startswith(b"\x89PNG"), thumb.text[:200]

        # restart the whole stack: new containers, same named volume
        t = time.monotonic()
        stack.run("down", "--timeout", "20", timeout=180)
        stack.run("up", "-d", "--wait", "--wait-timeout", str(WAIT_S), timeout=WAIT_S + 60)
        print(f"down + up (volume kept): {time.monotonic() - t:.1f} s")
        wait_for("the api after the restart", lambda: client.get("/healthz").status_code == 200, 60, stack)
        for name, body in accepted.items():
            model = client.get(f"/models/{body['model_id']}").json()
            assert model.get("status") == "ready", f"{name} after the restart: {model}"
        wait_for(
            "3 models in the index after the restart",
            lambda: readiness(client)["checks"].get("indexed_models", 0) >= 3,
            60,
            stack,
        )
        name, _, data = shapes[0]
        assert_finds_itself(client, name, data, accepted[name]["model_id"], stack)

        # two workers: both containers running and healthy, both heartbeating, ingestion still flows
        stack.run(
            "up", "-d", "--scale", "worker=2", "--wait", "--wait-timeout", str(WAIT_S), timeout=WAIT_S + 60
        )
        workers = service_states(stack, "worker")
        assert len(workers) == 2, f"expected 2 worker containers, got {workers}"
        assert all(w["State"] == "running" and w.get("Health") == "healthy" for w in workers), workers
        wait_for(
            "2 live workers in /readyz",
            lambda: readiness(client)["checks"].get("workers_alive", 0) >= 2,
            60,
            stack,
        )
        name, label, data = shapes[3]
        body = upload(client, name, label, data)
        wait_for(f"a worker to ingest {name}", job_done(client, body["job_id"]), 180, stack)
        wait_for(
            "4 models in the index",
            lambda: readiness(client)["checks"].get("indexed_models", 0) >= 4,
            60,
            stack,
        )
        assert_finds_itself(client, name, data, body["model_id"], stack)
    print(f"compose scenario: {time.monotonic() - t0:.1f} s")
