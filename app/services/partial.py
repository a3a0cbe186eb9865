"""Partial matching at query time: is the query a piece, and how do the candidates cover it?

A query whose rim (app.core.partial.rim_length: free boundary over √area, holes closed by a cap
included) is at least RIM_PARTIAL is taken for a piece. Its candidates are the GLOBAL_KEEP nearest models
of the global index and the COARSE_KEEP nearest by a coarse partial distance (the query's first
COARSE_POINTS samples) among the COARSE_SCAN nearest of the global index: the global ranking is what a
piece defeats, and it left the piece's class out of its top 200 for 8 % of SHREC'11's 60-85 % pieces,
the coarse pass for 1 % (docs/partial.md). The candidates are re-ranked by the local signatures'
score (app.core.partial_match: the distance less the weight of the share of the query for which the
candidate is among the VOTE_TOP nearest of the candidates scored, averaged with the scores of its
nearest fellow candidates in the index's space): the steps of app.core.piece_rank,
run here with the signatures read lazily and a deadline on each pass. A
closed query keeps the global ranking exactly. Every hit gets
forward and reverse scores either way.
Models described before the local signature existed (description format < 3) have none: they get no
scores and, in a re-ranking, follow the models that have one, in their global order.
The hits a piece's search returns (at most search.MAX_K) also get their matched region: the model
samples the query matched, which the page's 3D view colours.
How much of this was done (the models the coarse pass read, the candidates fully scored, each of how
many: past a deadline, fewer) and the seconds of each step are kept in a Work, which the search
response reports.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from app.core import piece_fit, piece_rank
from app.core.partial import LocalSignature
from app.core.partial_match import MUTUAL, PartialMatch, Region, head, match_many
from app.core.partial_match import regions as regions_of
from app.core.pipeline import LOCAL, load_local_and_noise
from app.services.context import ServiceContext
from app.storage import vocabularies as vocab_repo

# the piece's steps and their sizes are app.core.piece_rank's (the evaluation runs the same ones); here
# they run with the signatures read lazily and a deadline on each pass
RIM_PARTIAL = piece_rank.RIM_PARTIAL
GLOBAL_KEEP = piece_rank.GLOBAL_KEEP
COARSE_KEEP = piece_rank.COARSE_KEEP
COARSE_POINTS = piece_rank.COARSE_POINTS
COARSE_SCAN = piece_rank.COARSE_SCAN
RERANK = GLOBAL_KEEP + COARSE_KEEP  # at most this many candidates get a full match
COARSE_BUDGET_S = 1.0  # past it the models not yet read are no coarse candidates
CACHE_SIZE = 4096  # local signatures kept in memory (about 28 kB each with their surface)
# the scoring runs in the API process after the pooled describe, so it needs its own deadline: past it
# the remaining candidates are left unscored (they follow the scored ones, in their global order).
# 2.4-4.6 ms a candidate on 2 loaded cores: RERANK of them fit, a slow disk or a busy host does not
SCORE_BUDGET_S = 2.0
CHUNK = 16  # candidates scored between two looks at the clock
# the fits of a piece onto its likeliest candidates (app.core.piece_fit) have their own deadline, looked at
# between two fits; the first FIT_ALWAYS are always made. The screens of ~160 candidates take ~0.6 s and
# a fit ~15 ms: at 1 s held-out views lost 1.4 mAP and 0.017 NN, at 1.5 s nothing (docs/partial.md)
FIT_BUDGET_S = 1.5
FIT_ALWAYS = 4


@dataclass
class Work:
    """How much of one query's partial matching was done, and the seconds of each step.

    coarse_read / coarse_of: the models the coarse pass read of the nearest it was to read (0 / 0: no
    coarse pass: a whole query, or a collection no larger than GLOBAL_KEEP); scored / scored_of: the
    candidates reached by the full scoring of those chosen (a model without a local signature counts as
    reached: it has no score to compute). Fewer read than asked: COARSE_BUDGET_S (SCORE_BUDGET_S) cut it.
    fitted / fitted_of: the fits made of those chosen (0 / 0: no fit: a whole query); fit_cut:
    FIT_BUDGET_S stopped the screens or the fits (app.core.piece_fit.Fitted.cut).
    seconds: per step (coarse, score, vote, peers, fit, regions; search.py adds the hit records)."""

    coarse_read: int = 0
    coarse_of: int = 0
    scored: int = 0
    scored_of: int = 0
    fitted: int = 0
    fitted_of: int = 0
    fit_cut: bool = False
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def coarse_cut(self) -> bool:
        return self.coarse_read < self.coarse_of

    @property
    def score_cut(self) -> bool:
        return self.scored < self.scored_of


@dataclass(frozen=True)
class _Stored:
    local: LocalSignature | None
    input_noise: float  # NaN: not recorded


_NOTHING = _Stored(None, float("nan"))


class LocalCache:
    """What the re-rankings read of stored models' descriptions (the local signature, and the input
    noise the fusion re-rank weighs), by (path, mtime): a re-ingested model is read again. One read of
    a description serves both."""

    def __init__(self, size: int = CACHE_SIZE) -> None:
        self._size = size
        self._items: OrderedDict[tuple[str, int], _Stored] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, path: Path) -> LocalSignature | None:
        return self._entry(path).local

    def noise(self, path: Path) -> float | None:
        """The input displacement correlation (None: not recorded, or unreadable)."""
        noise = self._entry(path).input_noise
        return noise if math.isfinite(noise) else None

    def _entry(self, path: Path) -> _Stored:
        try:
            key = (str(path), path.stat().st_mtime_ns)
        except OSError:  # deleted a moment ago, or never described
            return _NOTHING
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]
        try:
            entry = _Stored(*load_local_and_noise(path))
        except (OSError, ValueError, KeyError):  # unreadable: no scores, never a failed search
            entry = _NOTHING
        with self._lock:
            self._items[key] = entry
            while len(self._items) > self._size:
                self._items.popitem(last=False)
        return entry


_CACHE = LocalCache()


def local_of(ctx: ServiceContext, model_id: int) -> LocalSignature | None:
    """A stored model's local signature (None: none stored, or unreadable), through the LRU."""
    return _CACHE.get(ctx.blobs.description_path(model_id))


def noise_of(ctx: ServiceContext, model_id: int) -> float | None:
    """A stored model's input displacement correlation (None: not recorded, or unreadable), through the
    same LRU and the same read as its local signature."""
    return _CACHE.noise(ctx.blobs.description_path(model_id))


def is_partial(query: LocalSignature | None, requested: bool | None) -> bool:
    """The caller's choice when given, else whether the query has a rim (app.core.piece_rank)."""
    return piece_rank.is_piece(query, requested)


def _matches(ctx: ServiceContext, query: LocalSignature, model_ids: Sequence[int],
             budget_s: float, mutual: bool = False) -> tuple[list[PartialMatch | None], int]:
    """(one PartialMatch per model (None: no signature, or not reached within budget_s; the first
    CHUNK are always scored), how many models were reached). mutual: with the mutual share (the score
    reads it when MUTUAL > 0)."""
    out: list[PartialMatch | None] = [None] * len(model_ids)
    deadline = time.monotonic() + budget_s
    reached = 0
    for start in range(0, len(model_ids), CHUNK):
        if start and time.monotonic() > deadline:
            break  # the rest unscored: the first chunk always is, so a query never gets nothing
        chunk = range(start, min(start + CHUNK, len(model_ids)))
        reached = chunk.stop
        signed = [(j, local_of(ctx, model_ids[j])) for j in chunk]
        have = [(j, sig) for j, sig in signed if sig is not None]
        found = match_many(query, [sig for _, sig in have], LOCAL, mutual=mutual)
        for (j, _), m in zip(have, found, strict=True):
            out[j] = m
    return out, reached


def candidates(ctx: ServiceContext, query: LocalSignature | None, model_ids: Sequence[int],
               work: Work | None = None) -> list[int]:
    """Indices into model_ids (the global order) of a piece's candidates, in global order: the first
    GLOBAL_KEEP and the COARSE_KEEP nearest by the coarse partial distance among the first COARSE_SCAN.
    work: gets the models the coarse pass read, of how many, and its seconds."""
    first = list(range(min(GLOBAL_KEEP, len(model_ids))))
    if query is None or len(model_ids) <= GLOBAL_KEEP:
        return first
    t = time.perf_counter()
    scan = model_ids[:COARSE_SCAN]
    coarse, read = _matches(ctx, head(query, COARSE_POINTS), scan, COARSE_BUDGET_S)
    if work is not None:
        work.coarse_read, work.coarse_of = read, len(scan)
        work.seconds["coarse"] = time.perf_counter() - t
    return piece_rank.chosen(len(model_ids), coarse, GLOBAL_KEEP, COARSE_KEEP)


def score(ctx: ServiceContext, query: LocalSignature | None, model_ids: Sequence[int],
          work: Work | None = None) -> list[PartialMatch | None]:
    """One PartialMatch per model (None where the query or the model has no local signature, or past
    SCORE_BUDGET_S). work: gets the candidates reached, of how many, and the seconds of the scoring and
    of the vote."""
    if query is None:
        return [None] * len(model_ids)
    t = time.perf_counter()
    found, reached = _matches(ctx, query, model_ids, SCORE_BUDGET_S, mutual=MUTUAL > 0)
    t_score = time.perf_counter()
    out = piece_rank.voted(query, found, LOCAL)
    if work is not None:
        work.scored, work.scored_of = reached, len(model_ids)
        work.seconds.update(score=t_score - t, vote=time.perf_counter() - t_score)
    return out


def stored_vectors(ctx: ServiceContext, vocabulary_id: int, model_ids: Sequence[int]) -> np.ndarray:
    """(n, d) the models' stored fused vectors under one version, a row of NaN for a model that has none
    (deleted a moment ago); (n, 0) when none has one."""
    with ctx.db.read() as conn:
        found = vocab_repo.vectors_of(conn, vocabulary_id, [int(i) for i in model_ids])
    if not found:
        return np.zeros((len(model_ids), 0))
    width = len(next(iter(found.values())))
    out = np.full((len(model_ids), width), np.nan)
    for j, model_id in enumerate(model_ids):
        if int(model_id) in found:
            out[j] = found[int(model_id)]
    return out


def ordered(ctx: ServiceContext, vocabulary_id: int | None, model_ids: Sequence[int],
            found: list[PartialMatch | None], work: Work | None = None,
            query: LocalSignature | None = None) -> tuple[list[int], list[PartialMatch | None]]:
    """(indices of model_ids in served order, the matches with their peers and fits set): the scored
    candidates' scores averaged with their nearest fellow candidates' (app.core.piece_rank.with_peers)
    from the stored vectors of those scored (at most RERANK) read in one query under `vocabulary_id`
    (None: no vectors, each its own score and no anchor); then the query fitted onto the most likely of
    them (fitted(), given the query); then ordered by piece_rank.by_score: the candidates the query
    lies on first, the rest by score, anchored on the first hit. Bounded work after the scoring's
    deadline. work: gets its seconds."""
    t = time.perf_counter()
    scored = [j for j, m in enumerate(found) if m is not None]
    out, vectors = list(found), None
    if vocabulary_id is not None and len(scored) >= 2:
        read = stored_vectors(ctx, vocabulary_id, [model_ids[j] for j in scored])
        if read.shape[1]:
            vectors = np.full((len(found), read.shape[1]), np.nan)
            vectors[scored] = read
            out = piece_rank.with_peers(found, vectors)
    if work is not None:
        work.seconds["peers"] = time.perf_counter() - t
    lead: list[int] = []
    if query is not None:
        t = time.perf_counter()
        out, done = fitted(ctx, query, model_ids, out, FIT_BUDGET_S)
        lead = piece_fit.leading([m.fit if m is not None else None for m in out])
        if work is not None:
            work.fitted, work.fitted_of, work.fit_cut = done.made, done.chosen, done.cut
            work.seconds["fit"] = time.perf_counter() - t
    return piece_rank.by_score(out, vectors, lead=lead), out


def fitted(ctx: ServiceContext, query: LocalSignature, model_ids: Sequence[int],
           found: list[PartialMatch | None],
           budget_s: float) -> tuple[list[PartialMatch | None], piece_fit.Fitted]:
    """(the matches with `fit` set, what the fits did): the candidates app.core.piece_fit chooses (those
    of most promise and the first by score), fitted most promise first until `budget_s` is spent (the
    first FIT_ALWAYS always): each model's signature from the LRU the scoring filled."""
    sigs = [local_of(ctx, model_ids[j]) if m is not None else None for j, m in enumerate(found)]
    done = piece_fit.fitted(query, sigs, found, LOCAL, time.monotonic() + budget_s, FIT_ALWAYS)
    return [replace(m, fit=f) if m is not None and f is not None else m
            for m, f in zip(found, done.fits, strict=True)], done


def regions(ctx: ServiceContext, query: LocalSignature | None, model_ids: Sequence[int],
            found: Sequence[PartialMatch | None]) -> list[Region | None]:
    """Where the query matched in each model (found: its PartialMatch, None: unscored): the k hits of a
    page, their signatures read from the cache the scoring filled, about a sixth of a match each."""
    out: list[Region | None] = [None] * len(model_ids)
    if query is None:
        return out
    have = [(j, sig, m.shift) for j, (model_id, m) in enumerate(zip(model_ids, found, strict=True))
            if m is not None and (sig := local_of(ctx, model_id)) is not None]
    got = regions_of(query, [sig for _, sig, _ in have], [shift for _, _, shift in have], LOCAL)
    for (j, _, _), r in zip(have, got, strict=True):
        out[j] = r
    return out
