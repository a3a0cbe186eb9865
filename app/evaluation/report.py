"""Table 2 as text and as JSON."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

from app.core.metrics import METRICS
from app.evaluation.results import EvaluationResult
from app.storage.blobs import atomic_write


def format_table(result: EvaluationResult) -> str:
    """Fixed-width Table 2; mAP in % as the paper prints it."""
    width = max([len(r.name) for r in result.rows] + [len("Row")])
    head = f"{'Row':<{width}}  {'NN':>6} {'FT':>6} {'ST':>6} {'E':>6} {'DCG':>6} {'mAP(%)':>7} {'d':>4}"
    head += f" {'ΔmAP':>7} {'s':>6}"
    spread = any("mAP_sd" in r.details for r in result.rows)
    head += f" {'sd':>5}" if spread else ""
    lines = [head, "-" * len(head)]
    for r in result.rows:
        s = r.scores
        delta = "" if r.delta_map is None else f"{100 * r.delta_map:+.2f}"
        lines.append(
            f"{r.name:<{width}}  {s['NN']:6.3f} {s['FT']:6.3f} {s['ST']:6.3f} {s['E']:6.3f} {s['DCG']:6.3f}"
            f" {100 * s['mAP']:7.2f} {r.d:>4} {delta:>7} {r.seconds:6.1f}"
            + (f" {100 * r.details['mAP_sd']:5.2f}" if "mAP_sd" in r.details else " " * 6 if spread else "")
        )
    ds = result.describe
    lines.append("-" * len(head))
    if spread:
        seeds = result.options.seeds
        lines.append(f"BoF lines: mean over {seeds} k-means seeds; sd = spread of their mAP (%)")
    lines.append(
        f"{result.shapes} shapes, {result.classes} classes; descriptions: {ds['computed']} computed, "
        f"{ds['cached']} from the cache in {ds['seconds']:.1f} s; total {result.seconds:.1f} s"
    )
    for key, info in ds["descriptions"].items():
        verts, kps = info["mean_vertices"], info["mean_keypoints"]
        lines.append(f"  [{key}] mean vertices {verts:.0f}, mean keypoints {kps:.1f}")
    if result.options.per_class:
        lines += format_losses(result)
    return "\n".join(lines)


def format_losses(result: EvaluationResult, below: float = 0.995, intruders: int = 4) -> list[str]:
    """For each BoF line (clean, and its noisy or other-folder queries): the classes under `below`
    mAP, worst first, and who intrudes into their first tier (counted over the class's queries,
    summed over seeds)."""
    out = []
    for r in result.rows:
        breakdown = r.details.get("per_class")
        if r.kind != "bof" or not breakdown:
            continue
        weak = sorted((c for c, v in breakdown.items() if v["mAP"] < below),
                      key=lambda c: breakdown[c]["mAP"])
        out.append(f"{r.name}: {len(weak)} of {len(breakdown)} classes below {100 * below:g} % mAP")
        for c in weak:
            who = ", ".join(f"{o} {n}" for o, n in list(breakdown[c]["intruders"].items())[:intruders])
            loss = 100 * (1 - breakdown[c]["mAP"]) / len(breakdown)
            out.append(f"  {c:<14} {100 * breakdown[c]['mAP']:6.2f}  (-{loss:.2f} of the mean)"
                       f"  first tier: {who}")
    return out


def to_json(result: EvaluationResult) -> dict[str, Any]:
    options = {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(result.options).items()}
    rows = []
    for r in result.rows:
        rows.append({
            "name": r.name,
            "kind": r.kind,
            **{m: _finite(r.scores[m]) for m in METRICS},
            "d": r.d,
            "delta_mAP": None if r.delta_map is None else _finite(r.delta_map),
            "reference": None if r.reference is None else r.reference.name,
            "seconds": round(r.seconds, 3),
            "details": r.details,
        })
    return {
        "directory": result.directory,
        "shapes": result.shapes,
        "classes": result.classes,
        "options": options,
        "describe": result.describe,
        "rows": rows,
        "seconds": round(result.seconds, 3),
    }


def write_json(result: EvaluationResult, path: str | Path) -> Path:
    """Write atomically (temporary file, fsync, rename)."""
    return atomic_write(Path(path), json.dumps(to_json(result), indent=2).encode())


def _finite(x: float) -> float | None:
    return None if math.isnan(x) else round(float(x), 6)
