"""The shipped vocabulary is what `make vocabulary` makes from today's code, not only from today's
describe parameters: a change of the describe code that moves the keypoints would otherwise ship words
fit on other descriptors (round 14 found the shipped file 27 training descriptors off the recipe)."""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.core.vocabulary import Vocabulary
from app.datasets.synthetic import generate

MAKEFILE = Path(__file__).resolve().parents[2] / "Makefile"


def _make_variable(name: str) -> int:
    """A `NAME ?= value` default of the Makefile, which `make vocabulary` generates its corpus with."""
    found = re.search(rf"^{name}\s*\?=\s*(\d+)\s*$", MAKEFILE.read_text(), re.MULTILINE)
    assert found, f"{name} is not set in {MAKEFILE}"
    return int(found.group(1))


@pytest.mark.slow
def test_make_vocabulary_reproduces_the_shipped_vocabulary(tmp_path):
    shipped = Vocabulary.load(str(resources.files("app") / "data" / "vocabulary" / "default"))
    corpus, refit_dir = tmp_path / "corpus-vocab", tmp_path / "vocabulary-default"
    generate(corpus, classes=_make_variable("VOCAB_CLASSES"), per_class=_make_variable("VOCAB_PER_CLASS"),
             seed=0)
    # the recipe's own command, as `make vocabulary` runs it (describe pool, k-means, fusion scales)
    assert main(["vocabulary", "fit", str(corpus), "--out", str(refit_dir), "--size", str(shipped.size),
                 "--run", shipped.run, "--seed", str(shipped.metadata["seed"]), "--processes", "2"]) == 0
    refit = Vocabulary.load(str(refit_dir))
    hint = "the describe code moved the descriptors: refit with `make vocabulary`"
    assert refit.metadata["describe"] == shipped.metadata["describe"], hint
    assert refit.metadata["trained_on_descriptors"] == shipped.metadata["trained_on_descriptors"], hint
    # the Shape-DNA scale depends on the spectra alone, the centres on k-means over the keypoints
    assert refit.fusion.dna == pytest.approx(shipped.fusion.dna, rel=1e-6), hint
    np.testing.assert_allclose(refit.centers, shipped.centers, atol=1e-4, err_msg=hint)
    assert refit.fusion.bof == pytest.approx(shipped.fusion.bof, rel=1e-4), hint
