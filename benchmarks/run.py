"""Run the benchmark suite: `python -m benchmarks.run [--short] [--only describe,search,...]`.

`make bench` runs `--short` (a few minutes on 2 cores). Every benchmark prints its table and writes
results/<name>.json; docs/performance.md holds the full-run figures and the commands.
"""

from __future__ import annotations

import argparse
import sys
import time
import traceback

from benchmarks import describe, quality, search, service, throughput

SUITE = {
    "describe": describe.main,
    "quality": quality.main,
    "throughput": throughput.main,
    "search": search.main,
    "service": service.main,
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--short", action="store_true", help="the short version of every benchmark")
    ap.add_argument("--only", default=",".join(SUITE), help=f"comma-separated subset of {','.join(SUITE)}")
    args = ap.parse_args(argv)
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in SUITE]
    if unknown:
        ap.error(f"unknown benchmark(s): {', '.join(unknown)}")
    failed = []
    for name in names:
        print(f"\n=== {name} {'(short)' if args.short else ''}", flush=True)
        t = time.perf_counter()
        try:
            SUITE[name](["--short"] if args.short else [])
        except Exception:  # one broken benchmark must not hide the others' figures
            traceback.print_exc()
            failed.append(name)
        print(f"=== {name}: {time.perf_counter() - t:.0f} s", flush=True)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
