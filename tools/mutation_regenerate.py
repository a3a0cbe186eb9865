"""Regenerate mutmut's mutants of named source files only, keeping every other module's results.

    .venv/bin/python tools/mutation_regenerate.py app/core/vocabulary.py app/core/pipeline.py

Why: `mutmut run` regenerates every changed file and then re-collects the whole test selection's
stats (tens of minutes at `nice 19` on the shared machine) before it runs a single mutant. This calls
mutmut's own per-file generator (mutmut.__main__.create_mutants_for_file: the same mutants/<path>,
.meta and .spans) for the named files and nothing else. As in mutmut, a function whose source hash
is unchanged keeps its recorded results; a changed or new function's mutants start "not run".
Other modules' .meta files are not opened. Run from the repository root; then screen the module
with tools/mutation_screen.py.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import Counter
from pathlib import Path

from mutation_report import equivalent_names, module_counts  # tools/ is sys.path[0] when run as a script

ROOT = Path(__file__).resolve().parents[1]


def summary(meta: Path) -> Counter[str]:
    """The module's counts as tools/mutation_report.py reports them (timeouts killed, equivalents apart)."""
    return module_counts(meta, equivalent_names(Path("docs/testing.md"))) if meta.exists() else Counter()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("paths", nargs="+", help="source files, relative to the repository root")
    args = parser.parse_args(argv)
    os.chdir(ROOT)
    from mutmut.__main__ import create_mutants_for_file

    for name in args.paths:
        path = Path(name)
        out = Path("mutants") / path
        meta = Path("mutants") / (name + ".meta")
        before = summary(meta)
        if out.exists():  # mutmut skips a file whose mutants are newer than its source: make them older
            st = path.stat()
            os.utime(out, (st.st_atime, st.st_mtime - 1))
        result = create_mutants_for_file(path, out)
        if result.error:
            raise result.error
        changed = sorted(result.changed_functions or ())
        print(f"{name}: before {dict(before)}, after {dict(summary(meta))}; changed functions: {changed}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
