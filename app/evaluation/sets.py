"""The shapes an evaluation ranks: a labelled database folder and, optionally, a query folder.

A query folder (`evaluate DIR --queries QDIR`) holds other meshes of the same classes, e.g. another
triangulation of every database shape (benchmarks/variants.py). When every query file has a database
file of the same relative name (its suffix aside), the two are the same shape: as with noisy queries,
that counterpart is left out of the query's ranking, so the line measures retrieval of the *other*
members of the class, and compares with the clean line. Otherwise each query ranks the whole database.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.core import metrics


class FolderError(ValueError):
    """The folder cannot be evaluated; the message says why."""


@dataclass(frozen=True)
class Folder:
    root: Path
    files: list[tuple[Path, str]]  # (path, content sha256), in labels.csv order
    labels: np.ndarray  # (N,) class names
    keys: list[str]  # relative names without suffix: how queries pair with database shapes


def read_folder(directory: str | Path) -> Folder:
    from app.datasets.folder import DatasetError, read_labelled_folder
    from app.evaluation.cache import content_sha256

    try:
        entries = read_labelled_folder(directory)
    except DatasetError as exc:
        raise FolderError(str(exc)) from exc
    root = Path(directory).resolve()
    labels = np.array([e.label for e in entries])
    files = [(e.path, content_sha256(e.path)) for e in entries]
    keys = [e.path.relative_to(root).with_suffix("").as_posix() for e in entries]
    return Folder(root, files, labels, keys)


def counterparts(database: Folder, queries: Folder) -> np.ndarray:
    """(q,) index of each query's database counterpart, or all -1 when the folders do not pair up
    (some query has no database file of its name, or its class differs)."""
    index = {key: i for i, key in enumerate(database.keys)}
    pairs = np.array([index.get(key, -1) for key in queries.keys])
    if np.any(pairs < 0) or np.any(database.labels[np.maximum(pairs, 0)] != queries.labels):
        return np.full(len(queries.keys), -1)
    return pairs


def cross_scores(
    distances: np.ndarray, query_labels: np.ndarray, labels: np.ndarray, pairs: np.ndarray
) -> tuple[dict[str, float], dict[str, dict]]:
    """Scores of queries against a database, psbTable's definitions (app.core.metrics).

    distances    : (q, N), row = query, column = database shape
    query_labels : (q,); labels : (N,)
    pairs        : (q,) database counterpart of each query, left out of its ranking, or all -1
    -> (mean scores, per-class {"mAP", "intruders"}), relevant = database shapes of the query's class;
       a class's intruders are the other classes in its queries' first tiers (each query's first
       R results, R = its relevant shapes), most frequent first (metrics.ranked_breakdown)
    """
    q, n = distances.shape
    order = np.argsort(distances, axis=1, kind="stable")  # (q, N), ties by index
    if np.all(pairs >= 0):
        order = order[order != pairs[:, None]].reshape(q, n - 1)
    ranked = labels[order]  # (q, L) class of each result
    relevant = ranked == query_labels[:, None]
    per_query = metrics.relevance_scores(relevant)
    # each query's first tier: as many results as it has relevant shapes
    per_class = metrics.ranked_breakdown(ranked, query_labels, relevant.sum(axis=1), per_query["mAP"])
    return metrics.mean_scores(per_query), per_class
