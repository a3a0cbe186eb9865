"""Variants in the stored collection: fingerprints at ingest, candidates from an in-memory index of
the stored fingerprints, geometric verification of the few nearest, relations kept with their evidence,
and reviewers' decisions. Advisory only: nothing here deletes, merges or refuses a model."""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable

import numpy as np

from app.core.mesh import InvalidMeshError, Mesh, load_mesh
from app.core.variants import DIM, FINGERPRINT_VERSION, Evidence, Prepared, relate
from app.core.variants.collection import fingerprints, shortlist
from app.core.variants.gate import may_relate_any
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

    def candidates(self, ctx: ServiceContext, queries: np.ndarray, exclude: int | None) -> list[int]:
        with self._lock:
            with ctx.db.read() as conn:
                ids, vectors, seq = variants_repo.fingerprints_since(
                    conn, self._seq, FINGERPRINT_VERSION, DIM
                )
            if len(ids):
                self._index.add(ids, vectors)
            self._seq = seq
            return shortlist(self._index, queries, exclude)

    def rows(self, model_id: int) -> np.ndarray:
        """(r, DIM) the fingerprints stored for a model (its whole and objects)."""
        with self._lock:
            return self._index.rows(model_id)


class PreparedCache:
    """The stored candidates' meshes, parsed and prepared (samples, k-d trees), kept for the next ingest
    that meets them: least recently used first out, at most `max_models` meshes and `max_vertices`
    vertices in all. Keyed by content (sha256, format), so a deleted model's entry is merely unused."""

    def __init__(self, max_models: int = 64, max_vertices: int = 2_000_000) -> None:
        self.max_models, self.max_vertices = max_models, max_vertices
        self._lock = threading.Lock()
        self._items: OrderedDict[tuple[str, str], Prepared] = OrderedDict()
        self._vertices = 0
        self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._items)

    def get(self, key: tuple[str, str], load: Callable[[], Mesh]) -> Prepared:
        with self._lock:
            found = self._items.get(key)
            if found is not None:
                self._items.move_to_end(key)
                self.hits += 1
                return found
            self.misses += 1
        prepared = Prepared(load())  # outside the lock: parsing a large file must not hold up others
        self.put(key, prepared)
        return prepared

    def put(self, key: tuple[str, str], prepared: Prepared) -> None:
        """Keep `prepared` as the stored file `key`'s mesh (a no-op when one is kept already), within
        the bounds."""
        n = prepared.mesh.n_vertices
        with self._lock:
            if key not in self._items and n <= self.max_vertices:
                self._items[key] = prepared
                self._vertices += n
                while len(self._items) > self.max_models or self._vertices > self.max_vertices:
                    _, old = self._items.popitem(last=False)
                    self._vertices -= old.mesh.n_vertices


_CACHES: dict[str, FingerprintCache] = {}
_PREPARED: dict[str, PreparedCache] = {}


def _key(ctx: ServiceContext) -> str:
    return ctx.settings.database_url or str(ctx.data_dir)


def _cache(ctx: ServiceContext) -> FingerprintCache:
    return _CACHES.setdefault(_key(ctx), FingerprintCache())


def prepared_cache(ctx: ServiceContext, replace: PreparedCache | None = None) -> PreparedCache:
    """This collection's cache of prepared candidates (`replace`: use that one from now on)."""
    if replace is not None:
        _PREPARED[_key(ctx)] = replace
    return _PREPARED.setdefault(_key(ctx), PreparedCache())


def stored_prepared(ctx: ServiceContext, sha256: str, file_type: str) -> Prepared:
    """A stored file's mesh, prepared, from the cache or read and parsed (InvalidMeshError, OSError)."""

    def load() -> Mesh:
        data = ctx.blobs.mesh_path(sha256, file_type).read_bytes()
        return load_mesh(data, file_type, ctx.settings.max_vertices)

    return prepared_cache(ctx).get((sha256, file_type), load)


def lookup(ctx: ServiceContext, vectors: np.ndarray) -> list[int]:
    """The stored models worth verifying for a mesh with these fingerprints (1 + objects, DIM)."""
    return _cache(ctx).candidates(ctx, vectors, exclude=None)


def detect(ctx: ServiceContext, model_id: int, mesh: Mesh) -> list[dict]:
    """Store the model's fingerprints, verify its nearest stored candidates, keep every relation that
    is more than `similar`; returns them as {model_id, name, relation, confidence} (best first)."""
    prepared = Prepared(mesh)
    vectors = fingerprints(prepared)
    candidates = _cache(ctx).candidates(ctx, vectors, exclude=model_id)
    with ctx.db.write() as conn:
        model = models_repo.get(conn, model_id)
        if model is None:
            return []  # deleted meanwhile
        variants_repo.put_fingerprints(conn, model_id, FINGERPRINT_VERSION, vectors)
    # `mesh` is the stored file's (both callers parse it from the blob as stored_prepared would): the
    # next ingests in this process that meet the model as a candidate neither re-read nor re-prepare it
    prepared_cache(ctx).put((model.sha256, model.file_type), prepared)
    # the gate rules out every pair of their fingerprints: `similar`, the file unread
    screened = [c for c in candidates if may_relate_any(vectors, _cache(ctx).rows(c))]
    with ctx.db.read() as conn:  # one connection for the candidates' records
        others = [models_repo.get(conn, c) for c in screened]
    found = []
    for other_id, other in zip(screened, others, strict=True):
        if other is None or other.status == "failed":
            continue
        try:
            ev = relate(prepared, stored_prepared(ctx, other.sha256, other.file_type))
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


def backfill(ctx: ServiceContext, progress: Callable[[int, int, int], None] | None = None) -> dict:
    """Fingerprints and links for the ready models that have none of this recipe version (stored
    before the variant step, or under an older FINGERPRINT_VERSION), oldest first, each as its ingest
    would have done it. Idempotent: a second run finds nothing to do. progress(done, total, model id)."""
    with ctx.db.read() as conn:
        todo = variants_repo.ready_without_fingerprints(conn, FINGERPRINT_VERSION)
    done, linked, skipped = 0, 0, []
    for n, model_id in enumerate(todo, start=1):
        with ctx.db.read() as conn:
            model = models_repo.get(conn, model_id)
        if model is None or model.status != "ready":
            continue  # deleted or re-queued meanwhile (its job does it)
        try:
            mesh = load_mesh(ctx.blobs.mesh_path(model.sha256, model.file_type).read_bytes(), model.file_type,
                             ctx.settings.max_vertices)
        except (InvalidMeshError, OSError) as exc:
            skipped.append({"model_id": model_id, "reason": str(exc)})
            continue
        found, _ = timed_detect(ctx, model_id, mesh)
        done += 1
        linked += len(found)
        if progress is not None:
            progress(n, len(todo), model_id)
    return {"missing": len(todo), "fingerprinted": done, "links": linked, "skipped": skipped,
            "version": FINGERPRINT_VERSION}


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
    if evidence.get("lies_on_other") is not None:  # which of the two lies on the other's surface
        out["lies_on_other"] = not evidence["lies_on_other"]
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
    "Evidence", "PreparedCache", "backfill", "brief", "decide", "detect", "lookup", "prepared_cache",
    "relations_with", "reverse", "timed_detect", "variants_of",
]
