"""Mutation score per module from mutmut 3's results (mutants/**/*.py.meta), for `make mutate`.

score = killed / (checked - equivalent), where killed counts mutants a test failed on or that timed
out, checked is every mutant with a result, and the equivalent ones are the mutant names listed in
docs/testing.md (a line starting "- `app....__mutmut_N`"). Mutants not yet run are counted apart.
"""

from __future__ import annotations

import json
import re
import sys
from collections import Counter
from pathlib import Path

KILLED = {1, 3, 37}  # a test failed, pytest internal error, caught by the type check
TIMEOUT = {36, 24, -24, 152, 255}  # over its CPU-time limit: counted as killed, shown apart
SURVIVED = 0
NO_TESTS = {5, 33}
EQUIVALENT = re.compile(r"^- `(app\.[\w.]+__mutmut_\d+)`", re.MULTILINE)


def equivalent_names(doc: Path) -> set[str]:
    """Mutant names listed as equivalent in docs/testing.md."""
    return set(EQUIVALENT.findall(doc.read_text())) if doc.exists() else set()


def module_counts(meta: Path, equivalent: set[str]) -> Counter[str]:
    """Counts of killed (timeouts included) / survived / no tests / equivalent / not run / other."""
    codes: dict[str, int | None] = json.loads(meta.read_text())["exit_code_by_key"]
    out: Counter[str] = Counter()
    for name, code in codes.items():
        if code is None:
            out["not run"] += 1
        elif code in KILLED:
            out["killed"] += 1
        elif code in TIMEOUT:
            out["killed"] += 1
            out["timeout"] += 1
        elif code == SURVIVED:
            out["equivalent" if name in equivalent else "survived"] += 1
        elif code in NO_TESTS:
            out["no tests"] += 1
        else:
            out["other"] += 1  # skipped, suspicious, segfault
    return out


def score(c: Counter[str]) -> float | None:
    """Killed share of the checked, non-equivalent mutants (no tests count as survivors)."""
    denominator = c["killed"] + c["survived"] + c["no tests"] + c["other"]
    return c["killed"] / denominator if denominator else None


def main(root: Path = Path(".")) -> int:
    equivalent = equivalent_names(root / "docs" / "testing.md")
    metas = sorted((root / "mutants").glob("app/**/*.py.meta"))
    if not metas:
        print("no mutmut results under mutants/ (run `make mutate` first)")
        return 1
    cols = ["killed", "(timeout)", "survived", "no tests", "other", "equivalent", "not run"]
    print(f"{'module':36} {'score':>6} " + " ".join(f"{c:>10}" for c in cols))
    for meta in metas:
        c = module_counts(meta, equivalent)
        if sum(c.values()) == c["not run"]:
            continue  # nothing of this module was run yet
        s = score(c)
        module = str(meta.relative_to(root / "mutants"))[: -len(".meta")]
        shown = f"{100 * s:5.1f}%" if s is not None else "    -"
        print(f"{module:36} {shown:>6} " + " ".join(f"{c[k.strip('()')]:>10}" for k in cols))
    return 0


if __name__ == "__main__":
    sys.exit(main())
