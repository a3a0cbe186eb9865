"""Retrieval statistics NN, FT, ST, E, DCG and mAP, as the shape-retrieval benchmarks define them.

Reference implementation followed line by line: `psbTable` of the Princeton Shape Benchmark utilities
(P. Shilane, `psbTable.cpp`: `calcTableTier`, `calcDCG`, `calcEF`), which the SHREC'11 non-rigid track
(Lian et al., "SHREC'11 Track: Shape Retrieval on Non-rigid 3D Watertight Meshes", 3DOR 2011) uses with
the same six measures. With C the size of the query's class (the query included), so that C - 1
shapes of the ranked list are relevant:

- ranking: every database shape but the query itself (psbTable sets the query's own dissimilarity to
  FLT_MAX and never reads the last slot), ascending distance; **equal distances are ordered by index**
  (psbTable's `compareRanks`; here a stable argsort), so results are deterministic.
- NN  : 1 if the first result is relevant, else 0.
- FT  : relevant results among the first C - 1, divided by C - 1 (recall at C - 1).
- ST  : relevant results among the first 2(C - 1) (at most N - 1), divided by C - 1.
- E   : over the first K = 32 results (at most N - 1), P = hits/K, R = hits/(C - 1),
        E = 2 / (1/P + 1/R), and 0 when there is no hit. A perfect ranking reaches E = 1 only
        if C - 1 = 32: for C = 20 the best possible E is 2·19 / (19 + 32) = 38/51 ≈ 0.745.
- DCG : G_1 + Σ_{i≥2} G_i / log2(i) (G_i = 1 if result i is relevant), divided by the same sum for
        the ideal list (the C - 1 relevant shapes first).
- AP  : the mean, over the C - 1 relevant results, of the precision at the rank where each is
        found (non-interpolated average precision, "precision at seen relevant documents");
        mAP is its mean over queries.

Means are micro averages (over queries, as psbTable's default). Queries with no relevant shape
(a class of one) have undefined FT/ST/E/DCG/AP and are left out of every mean; psbTable also
skips classes of two, which never occur in SHREC (20 per class).
"""

from __future__ import annotations

import numpy as np

METRICS: tuple[str, ...] = ("NN", "FT", "ST", "E", "DCG", "mAP")
E_CUTOFF = 32


def rankings(distances: np.ndarray) -> np.ndarray:
    """(N, N) distances, row i = query i -> (N, N-1) ranked database indices, query i left out.

    Ties are broken by index (stable sort), as psbTable does.
    """
    d = np.asarray(distances, dtype=np.float64)
    if d.ndim != 2 or d.shape[0] != d.shape[1]:
        raise ValueError(f"distances must be a square (N, N) matrix, got {d.shape}")
    n = d.shape[0]
    order = np.argsort(d, axis=1, kind="stable")  # (N, N)
    keep = order != np.arange(n)[:, None]  # drop the query from its own list
    return order[keep].reshape(n, n - 1)


def relevance_scores(relevant: np.ndarray) -> dict[str, np.ndarray]:
    """(q, L) bool, row = one query's ranked list marked relevant/not -> per-query metrics, each (q,).

    The number of relevant items of a row (C - 1) is counted from the row itself, so each row must
    hold the query's whole ranked list.
    """
    rel = np.asarray(relevant, dtype=bool)
    if rel.ndim != 2 or rel.shape[1] == 0:
        raise ValueError(f"relevance must be a (queries, list length >= 1) array, got {rel.shape}")
    q, length = rel.shape
    hits = np.cumsum(rel, axis=1)  # (q, L): relevant results among the first j+1
    n_rel = hits[:, -1]  # (q,) = C - 1
    valid = n_rel > 0
    safe = np.maximum(n_rel, 1)
    rows = np.arange(q)

    nn = rel[:, 0].astype(np.float64)
    ft = hits[rows, safe - 1] / safe
    st = hits[rows, np.minimum(2 * safe, length) - 1] / safe

    k = min(E_CUTOFF, length)
    found = hits[:, k - 1].astype(np.float64)
    precision, recall = found / k, found / safe
    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.where(found > 0, 2.0 * precision * recall / (precision + recall), 0.0)

    discount = np.ones(length)
    discount[1:] = 1.0 / np.log2(np.arange(2, length + 1))  # position i >= 2 weighs 1/log2(i)
    ideal = np.cumsum(discount)[safe - 1]  # (q,) DCG of the C - 1 relevant results first
    dcg = (rel @ discount) / ideal

    ranks = np.arange(1, length + 1)
    ap = (rel * (hits / ranks)).sum(axis=1) / safe

    out = {"NN": nn, "FT": ft, "ST": st, "E": e, "DCG": dcg, "mAP": ap}
    for name in ("FT", "ST", "E", "DCG", "mAP"):
        out[name] = np.where(valid, out[name], np.nan)
    return out


def per_query_scores(distances: np.ndarray, labels: np.ndarray) -> dict[str, np.ndarray]:
    """(N, N) distances (row = query) and (N,) labels -> {metric: (N,) per-query score}.

    Row i may come from a different description of shape i than column i (noisy queries against a
    clean database): the diagonal is still left out, only row i's ranking of the others counts.
    """
    d, labels = _checked(distances, labels)
    return _per_query(rankings(d), labels)


def _checked(distances: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    labels = np.asarray(labels)
    d = np.asarray(distances)
    if labels.ndim != 1 or labels.shape[0] != d.shape[0]:
        raise ValueError(f"labels must be ({d.shape[0]},), got {labels.shape}")
    if labels.shape[0] < 2:
        raise ValueError("retrieval needs at least two shapes")
    return d, labels


def _per_query(order: np.ndarray, labels: np.ndarray) -> dict[str, np.ndarray]:
    """(N, N-1) rankings (query left out) and (N,) labels -> {metric: (N,) per-query score}."""
    return relevance_scores(labels[order] == labels[:, None])


def mean_scores(per_query: dict[str, np.ndarray]) -> dict[str, float]:
    """{metric: (N,)} -> {metric: mean over the queries that have relevant shapes}."""
    out = {}
    for name in METRICS:
        values = per_query[name]
        if name == "NN":  # NN is defined for every query, but psbTable skips the same queries
            values = np.where(np.isnan(per_query["FT"]), np.nan, values)
        finite = values[~np.isnan(values)]
        out[name] = float(finite.mean()) if finite.size else float("nan")
    return out


def retrieval_scores(distances: np.ndarray, labels: np.ndarray) -> dict[str, float]:
    """(N, N) distances and (N,) labels -> {"NN", "FT", "ST", "E", "DCG", "mAP": mean score}."""
    return mean_scores(per_query_scores(distances, labels))


def ranked_scores(ranking: np.ndarray, labels: np.ndarray, query_label: object) -> dict[str, float]:
    """Scores of one query.

    ranking     : (L,) indices into `labels`, best first, the query itself already left out
    labels      : (N,) class of every database shape
    query_label : the query's class
    """
    ranking = np.asarray(ranking, dtype=np.int64)
    if ranking.ndim != 1 or ranking.size == 0:
        raise ValueError("ranking must be a non-empty 1-d array of indices")
    relevant = (np.asarray(labels)[ranking] == query_label)[None, :]
    return {name: float(v[0]) for name, v in relevance_scores(relevant).items()}


def scores_and_breakdown(
    distances: np.ndarray, labels: np.ndarray
) -> tuple[dict[str, float], dict[str, dict]]:
    """retrieval_scores and class_breakdown of the same distances, from one ranking."""
    d, labels = _checked(distances, labels)
    order = rankings(d)
    per_query = _per_query(order, labels)
    return mean_scores(per_query), _breakdown(order, labels, per_query["mAP"])


def class_breakdown(distances: np.ndarray, labels: np.ndarray) -> dict[str, dict]:
    """Where a ranking loses: per class, its mean AP and the classes that intrude into its first tier.

    distances : (N, N), row = query;  labels : (N,)
    -> {class: {"mAP": mean AP of its queries, "intruders": {other class: count}}}, the intruders
       counted over the class's queries in their first C - 1 results, most frequent first.
    """
    return scores_and_breakdown(distances, labels)[1]


def _breakdown(order: np.ndarray, labels: np.ndarray, ap: np.ndarray) -> dict[str, dict]:
    """class_breakdown from (N, N-1) rankings and (N,) per-query AP: each query's first tier is its
    class's C - 1 other members."""
    _, inverse, sizes = np.unique(labels, return_inverse=True, return_counts=True)
    return ranked_breakdown(labels[order], labels, sizes[inverse] - 1, ap)


def ranked_breakdown(
    ranked: np.ndarray, query_labels: np.ndarray, tiers: np.ndarray, ap: np.ndarray
) -> dict[str, dict]:
    """Per query class: the mean of its queries' AP (NaN ones left out) and the other classes found
    in their first tiers, most frequent first.

    ranked       : (q, L) class of each ranked result, row = query
    query_labels : (q,);  tiers : (q,) how many first results each query's tier holds;  ap : (q,)
    -> {class: {"mAP": float, "intruders": {other class: count}}}, the classes of query_labels only
    """
    in_tier = np.arange(ranked.shape[1])[None, :] < np.asarray(tiers)[:, None]  # (q, L)
    out: dict[str, dict] = {}
    for cls in sorted(set(query_labels.tolist())):
        members = np.flatnonzero(query_labels == cls)
        found = ranked[members][in_tier[members]]
        names, counts = np.unique(found[found != cls], return_counts=True)
        order = sorted(zip(names.tolist(), counts.tolist(), strict=True), key=lambda nc: (-nc[1], nc[0]))
        values = ap[members]
        values = values[~np.isnan(values)]
        out[str(cls)] = {"mAP": float(values.mean()) if values.size else float("nan"),
                         "intruders": {str(n): int(c) for n, c in order}}
    return out
