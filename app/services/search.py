"""Ranked answers: a query's BoF (or a stored model's) against the active index, with model metadata."""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, replace

import numpy as np

from app.core.object_rows import merge_rows
from app.core.partial import LocalSignature
from app.core.partial_match import Region
from app.core.piece_fit import PieceFit
from app.core.pipeline import ShapeDescription
from app.services import fusion_rerank
from app.services import partial as partial_mod
from app.services.context import ServiceContext
from app.services.errors import ConflictError, InvalidInputError, NotFoundError, NotReadyError
from app.services.live_index import LiveIndex
from app.services.piece_budget import PieceBudget
from app.storage import models as models_repo
from app.storage import vocabularies as vocab_repo
from app.storage.models import ModelRecord

MAX_K = 100


@dataclass(frozen=True)
class Hit:
    model: ModelRecord
    distance: float
    rank: int
    forward: float | None = None  # share of the query found in the model (app.services.partial)
    reverse: float | None = None  # share of the model the query covers
    partial: bool = False  # ranked by the partial re-ranking
    rerank: float | None = None  # the distance the hits are ordered by (services/fusion_rerank)
    region: Region | None = None  # a piece's: where it matched in the model (app.core.partial_match)
    part: int = 0  # the model's row that matched: 0 its whole, p > 0 its object row p (services/object_rows)
    fit: PieceFit | None = None  # a piece's: its fit onto this model (app.core.piece_fit), if it was fitted


@dataclass(frozen=True)
class SearchResult:
    hits: list[Hit]
    vocabulary_id: int
    seconds: dict[str, float]
    # how much of the partial matching was done (None: the query has no local signature, or a stored
    # model's similar search that is not a piece's)
    partial: partial_mod.Work | None = None


def check_k(k: int) -> int:
    if not 1 <= k <= MAX_K:
        raise InvalidInputError(f"k must be between 1 and {MAX_K}, got {k}")
    return k


def _allowed(ctx: ServiceContext, label: str | None) -> np.ndarray | None:
    if label is None or label == "":
        return None
    with ctx.db.read() as conn:
        return np.asarray(models_repo.ids_with_label(conn, label), np.int64)


def _hits(ctx: ServiceContext, dist: np.ndarray, ids: np.ndarray, k: int,
          rerank: np.ndarray | None = None, parts: np.ndarray | None = None) -> list[Hit]:
    with ctx.db.read() as conn:
        records = models_repo.get_many(conn, [int(i) for i in ids])
    hits: list[Hit] = []
    for j, (d, i) in enumerate(zip(dist, ids, strict=True)):
        rec = records.get(int(i))
        if rec is not None and len(hits) < k:  # deleted a moment ago: skip
            again = None if rerank is None else float(rerank[j])
            part = 0 if parts is None else int(parts[j])
            hits.append(Hit(rec, float(d), len(hits) + 1, rerank=again, part=part))
    return hits


def _rows_search(live: LiveIndex, vector: np.ndarray, k: int, allowed: np.ndarray | None,
                 vocabulary_id: int) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """The index's nearest models over their whole and object rows, a model at its nearest row (the k
    nearest of each index merged: at least k when the index holds them, the first k the k nearest
    models; _hits keeps k of those still stored): distances, model ids, the version, the matched rows
    (0: whole)."""
    dist, ids, vid = live.search(vector, k, allowed, vocabulary_id=vocabulary_id)
    dist, ids, parts = merge_rows(dist, ids, *live.search_objects(vector, k, allowed, vocabulary_id=vid))
    return dist, ids, vid, parts


def search_description(
    ctx: ServiceContext, live: LiveIndex, description: ShapeDescription, k: int, label: str | None = None,
    partial: bool | None = None, gate: PieceBudget | None = None,
) -> SearchResult:
    """The k nearest models; a piece (partial, or None and the query has a rim) re-ranks its
    candidates (app.services.partial) by their local signatures, holding a place of `gate` while it
    does (the API's bound on pieces matched at once; None: no bound). Every hit carries forward /
    reverse scores."""
    check_k(k)
    allowed = _allowed(ctx, label)
    piece = partial_mod.is_partial(description.local, partial)
    wanted = max(k, partial_mod.COARSE_SCAN) if piece else k
    for _ in range(3):  # a vocabulary swap between encode and search: encode again
        t = time.perf_counter()
        vid, vector = live.encode(description)
        t_encode = time.perf_counter() - t
        t = time.perf_counter()
        rerank, parts = None, None
        try:
            if not piece and fusion_rerank.applies(ctx, live):  # a piece is re-ranked by its rim instead
                rim = None if description.local is None else description.local.rim
                dist, ids, vid, rerank, parts = fusion_rerank.search(ctx, live, vector, wanted, allowed, vid,
                                                                     rim=rim, noise=description.input_noise)
            elif not piece:
                dist, ids, vid, parts = _rows_search(live, vector, wanted, allowed, vid)
            else:  # a piece's candidates are whole models: their local signatures re-rank them
                dist, ids, vid = live.search(vector, wanted, allowed, vocabulary_id=vid)
        except NotReadyError:
            if live.pair is None:
                raise
            continue
        t_search = time.perf_counter() - t
        t = time.perf_counter()
        found = _hits(ctx, dist, ids, wanted, rerank, parts)
        work = partial_mod.Work(seconds={"records": time.perf_counter() - t})
        with _place(gate, piece):
            hits = _scored(ctx, description.local, found, k, piece, work, vid)
        seconds = {"encode": t_encode, "search": t_search, "partial": time.perf_counter() - t}
        # the partial stage's steps (hit records, coarse pass, full scoring, vote, regions)
        seconds.update({f"partial.{step}": v for step, v in work.seconds.items()})
        return SearchResult(hits, vid, seconds, work if description.local is not None else None)
    raise NotReadyError("the vocabulary is being swapped; retry")


def _place(gate: PieceBudget | None, piece: bool) -> contextlib.AbstractContextManager[None]:
    """A place of the API's bound on pieces matched at once, for a piece; nothing for a whole query."""
    return gate.hold() if piece and gate is not None else contextlib.nullcontext()


def _scored(ctx: ServiceContext, local: LocalSignature | None, hits: list[Hit], k: int,
            piece: bool, work: partial_mod.Work | None = None, vocabulary_id: int | None = None) -> list[Hit]:
    """The first k hits with their forward / reverse scores against the query's local signature; a
    piece's candidates (app.services.partial) ordered by partial score, averaged with their nearest
    fellow candidates' under the version `vocabulary_id` that ranked them (None: each its own; models
    without a local signature after, in their global order). work: gets how much of the matching was
    done, and its steps' seconds."""
    if piece:  # the candidates include the global GLOBAL_KEEP >= k nearest: no other hit is needed
        ids = [h.model.id for h in hits]
        hits = [hits[j] for j in partial_mod.candidates(ctx, local, ids, work)]
    else:
        hits = hits[:k]
    found = partial_mod.score(ctx, local, [h.model.id for h in hits], work)
    if piece:
        order, found = partial_mod.ordered(ctx, vocabulary_id, [h.model.id for h in hits], found, work, local)
        hits, found = [hits[j] for j in order[:k]], [found[j] for j in order[:k]]
    where: list[Region | None] = [None] * len(hits)
    if piece:
        t = time.perf_counter()
        where = partial_mod.regions(ctx, local, [h.model.id for h in hits], found)
        if work is not None:
            work.seconds["regions"] = time.perf_counter() - t
    return [
        replace(h, rank=rank, forward=m.forward if m else None, reverse=m.reverse if m else None,
                partial=piece, region=r, fit=m.fit if m else None)
        for rank, (h, m, r) in enumerate(zip(hits, found, where, strict=True), start=1)
    ]


def similar(
    ctx: ServiceContext, live: LiveIndex, model_id: int, k: int, label: str | None = None,
    partial: bool | None = None, gate: PieceBudget | None = None,
) -> SearchResult:
    """Models nearest to a stored one (itself excluded), ranked as POST /search ranks the same mesh: a
    model with a rim (an open scan, a piece; partial None) or partial True is a piece, its candidates
    re-ranked by their local signatures (app.services.partial) with forward / reverse scores; otherwise
    the whole-shape ranking. Whole open scans gain by it (docs/partial.md: +2.4 to +3.0 mAP on the
    held-out scan columns), so a stored scan is not ranked worse than its own upload would be. A piece
    holds a place of `gate` while it is matched, as search_description's."""
    check_k(k)
    t = time.perf_counter()
    allowed = _allowed(ctx, label)
    for _ in range(3):  # a vocabulary swap between reading the vector and searching: read again
        pair = live.require()
        with ctx.db.read() as conn:
            model = models_repo.get(conn, model_id)
            vector = vocab_repo.vector_of(conn, model_id, pair.record.id) if model else None
        if model is None:
            raise NotFoundError(f"no model with id {model_id}")
        if vector is None:
            raise ConflictError(f"model {model_id} is {model.status}, not indexed: nothing to compare yet")
        # its rim (closed or open) and its input's noise (core.fusion): one read, through the LRU
        local = partial_mod.local_of(ctx, model_id)
        piece = partial_mod.is_partial(local, partial)
        rerank, parts = None, None
        try:
            if piece:  # the candidates come from the COARSE_SCAN nearest, as a piece's upload's do
                dist, ids, vid = live.search(vector, max(k, partial_mod.COARSE_SCAN) + 1, allowed,
                                             vocabulary_id=pair.record.id)
            elif fusion_rerank.applies(ctx, live):
                dist, ids, vid, rerank, parts = fusion_rerank.search(
                    ctx, live, vector, k, allowed, pair.record.id, model_id,
                    None if local is None else local.rim, partial_mod.noise_of(ctx, model_id))
            else:
                dist, ids, vid, parts = _rows_search(live, vector, k + 1, allowed, pair.record.id)
        except NotReadyError:
            if live.pair is None:
                raise
            continue
        keep = ids != model_id
        seconds = {"search": time.perf_counter() - t}
        if not piece:
            hits = _hits(ctx, dist[keep], ids[keep], k, None if rerank is None else rerank[keep],
                         None if parts is None else parts[keep])
            return SearchResult(hits, vid, seconds)
        t = time.perf_counter()
        found = _hits(ctx, dist[keep], ids[keep], int(keep.sum()))
        work = partial_mod.Work(seconds={"records": time.perf_counter() - t})
        with _place(gate, True):
            hits = _scored(ctx, local, found, k, True, work, vid)
        seconds["partial"] = time.perf_counter() - t
        seconds.update({f"partial.{step}": v for step, v in work.seconds.items()})
        return SearchResult(hits, vid, seconds, work if local is not None else None)
    raise NotReadyError("the vocabulary is being swapped; retry")
