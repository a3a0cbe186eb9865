"""Shared helpers: a plain-text table, JSON results under results/, machine facts, BLAS pinning."""

from __future__ import annotations

import json
import os
import platform
import resource
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]  # children run `python -m ...` from here
RESULTS_DIR = Path(os.environ.get("SHAPEBAG_RESULTS", "results"))


def table(rows: Sequence[dict], columns: Sequence[str] | None = None, title: str | None = None) -> str:
    """Render dict rows as an aligned text table (floats with 3 significant decimals)."""
    if not rows:
        return f"{title or ''}\n(no rows)\n"
    columns = list(columns or rows[0].keys())
    cells = [[_fmt(r.get(c, "")) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(columns)]
    lines = [title] if title else []
    lines.append("  ".join(c.rjust(w) for c, w in zip(columns, widths, strict=True)))
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(v.rjust(w) for v, w in zip(row, widths, strict=True)) for row in cells]
    return "\n".join(lines) + "\n"


def p50_p95(values: Sequence[float]) -> tuple[float, float]:
    """The median and the 95th percentile of `values`; (nan, nan) for none."""
    v = np.asarray(values, dtype=np.float64)
    return (float(np.percentile(v, 50)), float(np.percentile(v, 95))) if len(v) else (np.nan, np.nan)


def _fmt(value: object) -> str:
    if isinstance(value, float):
        if value == 0.0:
            return "0"
        if abs(value) >= 100:
            return f"{value:.0f}"
        if abs(value) >= 1:
            return f"{value:.2f}"
        return f"{value:.3g}" if abs(value) >= 1e-3 else f"{value:.1e}"
    return str(value)


def machine() -> dict:
    """What the figures were measured on."""
    info = {
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "load_average_1m": os.getloadavg()[0],
    }
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["cpu"] = line.split(":", 1)[1].strip()
                break
        mem = Path("/proc/meminfo").read_text().splitlines()[0].split()
        info["memory_gb"] = round(int(mem[1]) / 2**20, 1)
    except OSError:
        pass
    return info


def write_json(name: str, payload: dict) -> Path:
    """results/<name>.json with the machine and a UTC timestamp added."""
    RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    path = RESULTS_DIR / f"{name}.json"
    doc = {"benchmark": name, "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "machine": machine()}
    doc.update(payload)
    path.write_text(json.dumps(doc, indent=2, default=str))
    return path


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, in MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")


def thread_env(n: int | None) -> dict[str, str]:
    """os.environ for a child process with BLAS/OpenMP limited to n threads (None: library default)."""
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARS}
    if n is not None:
        env.update({var: str(n) for var in THREAD_VARS})
    return env


def pin_threads(n: int | None = 1) -> None:
    """Limit the BLAS/OpenMP pools already loaded in this process (numpy's and scipy's OpenBLAS)."""
    if n is None:
        return
    import scipy.linalg  # noqa: F401  (load scipy's own OpenBLAS so that the limit reaches it)
    import scipy.sparse.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    threadpool_limits(n)
