"""Screen mutmut's mutants against a few fast test files, recording kills in mutants/*.meta.

    .venv/bin/python tools/mutation_screen.py 'app.api.uploads.*' --tests tests/api/test_uploads.py

Why: mutmut runs *every* test that reached a mutant's function, so each survivor (equivalent or
not) pays for the slowest of them (a 12 s TestClient run, a seeded data directory): on a shared,
loaded machine at `nice 19` that is minutes per survivor. This runs the mutants mutmut generated
(mutants/, same trampolines, MUTANT_UNDER_TEST) in a forked child per mutant against only the named
test files, quickest first (tools/mutmut_fastest_first), with `-x` and a wall-clock limit.

Recorded in the module's .meta, as mutmut would: a test failed -> 1 (killed); all passed -> 0
(survived: conservative, a slower test left out might have killed it; docs/testing.md lists which
mutants were screened and with which files). A run past the limit or a crash is not recorded (left
for `make mutate`), unless --timeouts-killed: then a run past the limit is recorded as a timeout
(-24), which mutmut and tools/mutation_report.py count as killed (use a limit well above the named
tests' own time). Only mutants without a result are run, unless --rerun. Run `make mutate` (or
`mutmut run`) once first: it generates mutants/ and copies the tests; this copies tests/ and
tools/ again so new test files are seen.
"""

from __future__ import annotations

import argparse
import fcntl
import fnmatch
import io
import json
import os
import shutil
import signal
import sys
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MUTANTS = ROOT / "mutants"


def metas() -> dict[str, Path]:
    """Mutant name -> the .meta file that holds its result."""
    out = {}
    for meta in MUTANTS.glob("app/**/*.py.meta"):
        for name in json.loads(meta.read_text())["exit_code_by_key"]:
            out[name] = meta
    return out


def record(meta: Path, name: str, code: int, seconds: float) -> None:
    # two screens of one module read-modify-write the same .meta: a lock keeps each update whole
    # (unlocked, concurrent writes once left a corrupt gltf.py.meta), a rename keeps the file whole
    with open(meta.with_name(meta.name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        data = json.loads(meta.read_text())
        data["exit_code_by_key"][name] = code
        data.setdefault("durations_by_key", {})[name] = seconds
        tmp = meta.with_name(meta.name + ".tmp")
        tmp.write_text(json.dumps(data, indent=4))
        os.replace(tmp, meta)


def run_one(name: str, tests: list[str], limit_s: float) -> int | None:
    """pytest on `tests` with mutant `name` active, in a forked child: its exit code, None past the limit."""
    pid = os.fork()
    if pid == 0:
        os.environ["MUTANT_UNDER_TEST"] = name
        import pytest

        sink = io.StringIO()
        with redirect_stdout(sink), redirect_stderr(sink):
            code = pytest.main(
                [
                    "-x",
                    "-q",
                    "--rootdir=.",
                    "-p",
                    "no:cacheprovider",
                    "-p",
                    "no:randomly",
                    "-p",
                    "tools.mutmut_fastest_first",
                    *tests,
                ]
            )
        os._exit(int(code))
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        time.sleep(0.05)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("patterns", nargs="+", help="mutant-name globs")
    parser.add_argument("--tests", nargs="+", required=True)
    parser.add_argument("--limit", type=float, default=120.0, help="wall-clock seconds per mutant")
    parser.add_argument("--rerun", action="store_true", help="run mutants that already have a result")
    parser.add_argument(
        "--timeouts-killed",
        action="store_true",
        help="record a run past --limit as a timeout (-24, counted as killed, as mutmut does)",
    )
    args, extra = parser.parse_known_args(argv)  # unknown options (--deselect=...) go to pytest
    args.tests += extra
    where = metas()
    names = sorted(n for n in where if any(fnmatch.fnmatchcase(n, p) for p in args.patterns))
    if not args.rerun:
        names = [n for n in names if json.loads(where[n].read_text())["exit_code_by_key"][n] is None]
    shutil.copytree(ROOT / "tests", MUTANTS / "tests", dirs_exist_ok=True)
    shutil.copytree(ROOT / "tools", MUTANTS / "tools", dirs_exist_ok=True)
    link = ROOT / "shared"  # the tests find ../shared/datasets one level deeper under mutants/
    made = not link.exists()
    if made:
        link.symlink_to("../shared")
    os.chdir(MUTANTS)
    sys.path.insert(0, str(MUTANTS))
    import pytest

    with redirect_stdout(io.StringIO()):  # import the tests and the code once; each fork starts warm
        pytest.main(["-q", "--collect-only", "--rootdir=.", "-p", "no:cacheprovider", *args.tests])
    counts = {"killed": 0, "survived": 0, "not recorded": 0}
    try:
        for name in names:
            t = time.monotonic()
            code = run_one(name, args.tests, args.limit)
            seconds = time.monotonic() - t
            if code == 1:
                record(where[name], name, 1, seconds)
                counts["killed"] += 1
            elif code == 0:
                record(where[name], name, 0, seconds)
                counts["survived"] += 1
                print(f"survived  {name}", flush=True)
            elif code is None and args.timeouts_killed:
                record(where[name], name, -24, seconds)
                counts["killed"] += 1
                print(f"timeout   {name} (recorded as a timeout)", flush=True)
            else:
                counts["not recorded"] += 1
                print(f"{'timeout' if code is None else f'exit {code}':9} {name} (not recorded)", flush=True)
    finally:
        if made:
            link.unlink()
    print(", ".join(f"{v} {k}" for k, v in counts.items()), f"of {len(names)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
