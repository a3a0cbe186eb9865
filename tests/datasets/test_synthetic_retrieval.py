"""Does HKS-BoF tell the synthetic body plans apart? (slow: describes every shape)

Run as a script to print the figures:  python tests/datasets/test_synthetic_retrieval.py [classes per_class]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from app.core.mesh import load_mesh
from app.core.pipeline import describe
from app.core.vocabulary import Vocabulary, l1_distance
from app.datasets.folder import read_labelled_folder
from app.datasets.synthetic import generate


def average_precision(ranked_labels: np.ndarray, label: str) -> float:
    """AP of one ranked list (query excluded): mean of precision at each relevant rank."""
    hits = ranked_labels == label
    if not hits.any():
        return 0.0
    precision = np.cumsum(hits) / np.arange(1, len(hits) + 1)
    return float(precision[hits].mean())


def measure(classes: int = 6, per_class: int = 8, seed: int = 0) -> dict[str, float]:
    """Generate, describe, fit a 64-word vocabulary, encode; leave-one-out L1 retrieval figures."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        rows = read_labelled_folder(generate(Path(tmp), classes, per_class, seed))
        t1 = time.perf_counter()
        descriptions = [describe(load_mesh(r.path)) for r in rows]
        t2 = time.perf_counter()
    labels = np.array([r.label for r in rows])
    vocab = Vocabulary.fit(descriptions, size=64, seed=0)
    bof = np.stack([vocab.encode(d) for d in descriptions])  # (shapes, 64)
    dist = l1_distance(bof, bof)
    np.fill_diagonal(dist, np.inf)
    order = np.argsort(dist, axis=1, kind="stable")[:, :-1]  # drop the query itself (last: inf)
    nn = float((labels[order[:, 0]] == labels).mean())
    ap = [average_precision(labels[order[i]], labels[i]) for i in range(len(labels))]
    return {
        "shapes": float(len(rows)), "classes": float(classes), "nn": nn, "map": float(np.mean(ap)),
        "chance_map": 1.0 / classes, "generate_s": t1 - t0, "describe_s": t2 - t1,
    }


@pytest.mark.slow
def test_hks_bof_separates_the_body_plans() -> None:
    figures = measure(classes=6, per_class=4)
    # chance: NN ~ 3/23 = 0.13 and mAP ~ 0.17. Measured at 64d3fbe (defaults of issue 11): NN 1.0,
    # mAP 0.972 on this corpus (seed 0); 0.955 and 0.955 on seeds 1 and 2 (NN 1.0). The margins: one
    # wrong nearest neighbour of 24 (0.958), and mAP 0.04 below the measure, twice the spread between
    # corpora, so a change to the HKS or the BoF that costs retrieval fails here.
    assert figures["nn"] >= 0.95, figures
    assert figures["map"] >= 0.93, figures


if __name__ == "__main__":
    args = [int(a) for a in sys.argv[1:3]]
    for key, value in measure(*args).items():
        print(f"{key:12s} {value:.3f}")
