"""The evaluation package's imports: the report reads the result types, never the harness."""

from __future__ import annotations

import subprocess
import sys


def test_the_report_imports_without_the_harness() -> None:
    # a fresh interpreter: this test process may already have imported the harness
    code = "import sys, app.evaluation.report; print('app.evaluation.harness' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_the_serving_layer_does_not_import_the_evaluation() -> None:
    code = ("import sys, app.main; "
            "print(sorted(m for m in sys.modules if m.startswith('app.evaluation')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
