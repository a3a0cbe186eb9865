"""Variants in the stored collection: fingerprints at ingest, candidates from an in-memory index of
the stored fingerprints, geometric verification of the few nearest, relations kept with their evidence,
and reviewers' decisions. Advisory only: nothing here deletes, merges or refuses a model."""

from __future__ import annotations

import logging
import threading
import time

import numpy as np

from app.core.mesh import InvalidMeshError, Mesh, load_mesh
from app.core.variants import DIM, FINGERPRINT_VERSION, Evidence, Prepared, relate
from app.core.variants.collection import fingerprints, shortlist
from app.core.variants.index import FingerprintIndex
from app.services.context import ServiceContext
from app.services.errors import InvalidInputError, NotFoundError
from app.storage import models as models_repo
from app.storage import variants as variants_repo

log = logging.getLogger(__name__)
DECISIONS = ("keep_both", "not_variant")
REVERSED = {"part_of": "contains", "contains": "part_of"}


class FingerprintCache:
    """This process's copy of the stored fingerprints, topped up from the database by sequence number
    (rows of deleted models stay until restart; their verification finds no model and is skipped)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._seq = 0
        self._index = FingerprintIndex()

    def candidates(self, ctx: ServiceContext, queries: np.ndarray, exclude: int) -> list[int]:
        with self._lock:
            with ctx.db.read() as conn:
                ids, vectors, seq = variants_repo.fingerprints_since(
                    conn, self._seq, FINGERPRINT_VERSION, DIM
                )
            if len(ids):
                self._index.add(ids, vectors)
            self._seq = seq
            return shortlist(self._index, queries, exclude)


_CACHES: dict[str, FingerprintCache] = {}


def _cache(ctx: ServiceContext) -> FingerprintCache:
    key = ctx.settings.database_url or str(ctx.data_dir)
    return _CACHES.setdefault(key, FingerprintCache())


def detect(ctx: ServiceContext, model_id: int, mesh: Mesh) -> list[dict]:
    """Store the model's fingerprints, verify its nearest stored candidates, keep every relation that
    is more than `similar`; returns them as {model_id, name, relation, confidence} (best first)."""
    prepared = Prepared(mesh)
    vectors = fingerprints(prepared)
    candidates = _cache(ctx).candidates(ctx, vectors, exclude=model_id)
    with ctx.db.write() as conn:
        if models_repo.get(conn, model_id) is None:
            return []  # deleted meanwhile
        variants_repo.put_fingerprints(conn, model_id, FINGERPRINT_VERSION, vectors)
    found = []
    for other_id in candidates:
        with ctx.db.read() as conn:
            other = models_repo.get(conn, other_id)
        if other is None or other.status == "failed":
            continue
        try:
            data = ctx.blobs.mesh_path(other.sha256, other.file_type).read_bytes()
            ev = relate(prepared, Prepared(load_mesh(data, other.file_type, ctx.settings.max_vertices)))
        except (InvalidMeshError, OSError) as exc:  # a stored file gone or unreadable: no evidence
            log.warning("variant check of model %s against %s skipped: %s", model_id, other_id, exc)
            continue
        if ev.relation == "similar":
            continue
        with ctx.db.write() as conn:
            if models_repo.get(conn, model_id) is None or models_repo.get(conn, other_id) is None:
                continue
            variants_repo.put_link(conn, model_id, other_id, ev.relation, ev.confidence, ev.to_dict())
        found.append({"model_id": other_id, "name": other.name, "relation": ev.relation,
                      "confidence": ev.confidence})
    return sorted(found, key=lambda f: -f["confidence"])


def timed_detect(ctx: ServiceContext, model_id: int, mesh: Mesh) -> tuple[list[dict], float]:
    """detect() and its seconds; a numerical failure is logged and finds nothing (the ingest goes on)."""
    t = time.perf_counter()
    try:
        found = detect(ctx, model_id, mesh)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        log.warning("variant detection for model %s failed: %s", model_id, exc)
        found = []
    return found, time.perf_counter() - t


def variants_of(ctx: ServiceContext, model_id: int) -> list[dict]:
    """The model's stored relations seen from it (a relation found the other way round is reversed),
    each with the other model's name and the latest reviewer decision about the pair, best first."""
    with ctx.db.read() as conn:
        if models_repo.get(conn, model_id) is None:
            raise NotFoundError(f"no model with id {model_id}")
        links = variants_repo.links_of(conn, model_id)
        decisions = variants_repo.decisions_of(conn, model_id)
        names = models_repo.get_many(conn, [link["other_id"] if link["model_id"] == model_id
                                            else link["model_id"] for link in links])
    out = []
    for link in links:
        forward = link["model_id"] == model_id
        other = link["other_id"] if forward else link["model_id"]
        evidence = link["evidence"] if forward else reverse(link["evidence"])
        if other not in names:
            continue
        decision = decisions.get(other)
        out.append({"model_id": other, "name": names[other].name, **evidence,
                    "decision": {**decision, "model_id": model_id, "other_id": other} if decision else None})
    return out


def brief(ctx: ServiceContext, model_id: int) -> list[dict]:
    """variants_of() in short: {model_id, name, relation, confidence} each."""
    keys = ("model_id", "name", "relation", "confidence")
    return [{k: v[k] for k in keys} for v in variants_of(ctx, model_id)]


def relations_with(ctx: ServiceContext, model_id: int) -> dict[int, str]:
    """{other model id: relation seen from model_id} for annotating search hits."""
    with ctx.db.read() as conn:
        links = variants_repo.links_of(conn, model_id)
    out = {}
    for link in links:
        if link["model_id"] == model_id:
            out[link["other_id"]] = link["relation"]
        else:
            out[link["model_id"]] = REVERSED.get(link["relation"], link["relation"])
    return out


def reverse(evidence: dict) -> dict:
    """The same evidence seen from the other model: part_of <-> contains, forward <-> reverse, the
    inverse transform and scale."""
    out = dict(evidence)
    out["relation"] = REVERSED.get(evidence["relation"], evidence["relation"])
    out["forward"], out["reverse"] = evidence["reverse"], evidence["forward"]
    out["scale"] = 1.0 / evidence["scale"]
    out["transform"] = np.linalg.inv(np.asarray(evidence["transform"])).tolist()
    return out


def decide(ctx: ServiceContext, model_id: int, other_id: int, decision: str, note: str | None) -> dict:
    """Record a reviewer's decision about a pair; it changes nothing else (no model is touched)."""
    if decision not in DECISIONS:
        raise InvalidInputError(f"decision must be one of {', '.join(DECISIONS)}")
    if model_id == other_id:
        raise InvalidInputError("a decision is about two different models")
    with ctx.db.write() as conn:
        for i in (model_id, other_id):
            if models_repo.get(conn, i) is None:
                raise NotFoundError(f"no model with id {i}")
        when = variants_repo.add_decision(conn, model_id, other_id, decision, note)
    return {"model_id": model_id, "other_id": other_id, "decision": decision, "note": note,
            "decided_at": when}


__all__ = [
    "Evidence", "brief", "decide", "detect", "relations_with", "reverse", "timed_detect", "variants_of",
]
