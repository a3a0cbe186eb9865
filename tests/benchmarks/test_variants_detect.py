"""benchmarks/variants_detect.py's re-triangulated recall with and without the copies that lost area."""

from __future__ import annotations

from benchmarks.variants_detect import kept_surface


def _pair(got: str, area: float, truth: str = "retriangulated") -> dict:
    return {"truth": truth, "got": got, "area_ratio": area}


def test_kept_surface_counts_by_hand() -> None:
    pairs = [_pair("retriangulated", 1.0), _pair("retriangulated", 0.95), _pair("similar", 1.02),
             _pair("similar", 0.61), _pair("retriangulated", 0.85), _pair("similar", 1.0, truth="similar")]
    line = kept_surface(pairs)
    assert "recall 3/5" in line  # every true pair
    assert "without the 2 copies" in line and ": 2/3 (0.667)" in line  # 0.61 and 0.85 left out


def test_calibration_puts_the_gate_s_pairs_on_a_row_of_their_own() -> None:
    from benchmarks.variants_detect import calibration

    def pair(conf: float, got: str, truth: str, screened: bool = False) -> dict:
        return {"confidence": conf, "got": got, "truth": truth, "looked_up": True, "screened": screened}

    rows = calibration([pair(0.95, "retriangulated", "retriangulated"), pair(0.95, "similar", "moved"),
                        pair(1.0, "similar", "similar", True), pair(1.0, "similar", "retriangulated", True),
                        pair(1.0, "similar", "similar", True)])
    got = [(r["confidence"], r["pairs"]) for r in rows]
    assert got == [("[0.90, 0.99)", 2), ("ruled out by the gate", 3)]
    assert rows[0]["right"] == 0.5 and abs(rows[1]["right"] - 2 / 3) < 1e-12
