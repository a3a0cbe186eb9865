"""benchmarks.fusion_offline end to end on a tiny labelled folder with hand-made cached descriptions."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from app.core.pipeline import ShapeDescription
from app.core.vocabulary import Vocabulary
from app.evaluation.cache import content_sha256
from benchmarks import fusion_offline

RULES = ("BoF", "DNA", "DNA part", "served", "RRF 60", "local 10", "adaptive/all", "adaptive",
         "adaptive+pieces")


def _description(rng: np.random.Generator, centre: float) -> ShapeDescription:
    n = 40
    hks = np.zeros((n, 100), np.float32)
    hks[:, [19, 39, 59, 79]] = centre + 0.05 * rng.random((n, 4))  # run5's four time scales
    eigenvalues = np.concatenate([[0.0], np.cumsum(1 + centre + 0.01 * rng.random(40))])
    return ShapeDescription(hks=hks, weights=np.full(n, 1 / n, np.float32), keypoints=np.ones(n, bool),
                            eigenvalues=eigenvalues, input_vertices=n, input_noise=0.8)


def test_it_prints_every_rule_per_column_and_skips_what_is_not_cached(tmp_path: Path, capsys) -> None:
    rng = np.random.default_rng(0)
    folder, cache = tmp_path / "col", tmp_path / "cache"
    folder.mkdir()
    cache.mkdir()
    lines, descs = ["file,class"], []
    for i in range(8):
        path = folder / f"s{i}.obj"
        path.write_text(f"# shape {i}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
        lines.append(f"s{i}.obj,{'ab'[i % 2]}")
        d = _description(rng, centre=float(i % 2))
        d.save(cache / f"{content_sha256(path)}.npz")
        descs.append(d)
    (folder / "labels.csv").write_text("\n".join(lines) + "\n")
    features = np.concatenate([d.hks[:, [19, 39, 59, 79]] for d in descs])
    vocab = Vocabulary.fit_features(features, size=4, run="run5").with_fusion(descs)
    vocab.save(tmp_path / "vocab")

    fusion_offline.main([str(folder), f"{folder}@0.01", "--cache", str(cache), "--vocabulary",
                         str(tmp_path / "vocab")])
    out = capsys.readouterr().out
    assert all(rule in out for rule in RULES)
    row = next(line for line in out.splitlines() if line.startswith(str(folder)[-44:]))
    maps = [float(m) for m in re.findall(r"(\d+\.\d+) \(", row)]
    assert len(maps) == len(RULES)
    assert maps[0] == 100.0 and all(0 < m <= 100 for m in maps)  # the two classes apart in BoF
    assert "not cached, skipped" in out  # the noisy queries were never described
    assert out.splitlines()[-1].startswith("worst against max(BoF, DNA)")
