"""The cross-path benchmark's comparison and report (benchmarks/bench_cross_path.py):
a CoR shift is measured in the reference interval's half-widths, differing
claims and verdicts are flagged, rows of other code are left out and counted."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

import bench_cross_path as bench  # noqa: E402
from lss_fmu.design import CORS  # noqa: E402


def _ident(config: str, shift: float = 0.0, claim: bool = True, stamp: str = "now") -> dict:
    x = {n: 0.5 for n in CORS}
    x["contact.e_SW"] += shift
    iv = {n: {"lower": 0.45, "upper": 0.55, "identifiable": claim if n == "contact.e_SW" else True} for n in CORS}
    return {"case": "identify_m20", "config": config, "x": x, "truth": {n: 0.5 for n in CORS}, "f": 7.0,
            "f_truth": 7.0, "intervals": iv, "stamp": stamp, "blas": ["SkylakeX"], "cpu_s": 1.0, "code": "abc"}


def _loop(config: str, found, stamp: str = "now") -> dict:
    return {"case": "loop_mass", "config": config, "found": found, "outcome": "confirmed" if found else "nothing",
            "amplitude": 0.25 if found else None, "stamp": stamp, "blas": [], "cpu_s": 1.0, "code": "abc"}


def test_shifts_are_in_half_intervals_and_differences_are_flagged():
    rows = [_ident("scalar"), _ident("avx2", shift=0.01), _ident("avx512", claim=False),
            _loop("scalar", ["mass"]), _loop("avx2", ["mass"]), _loop("avx512", [])]
    cmp = bench.compare(rows)
    assert cmp["identify_m20"]["avx2"]["shift_over_halfwidth"]["contact.e_SW"] == pytest.approx(0.2)
    assert cmp["identify_m20"]["avx2"]["same_claims"] and not cmp["identify_m20"]["avx512"]["same_claims"]
    assert cmp["loop_mass"]["avx2"]["same_verdict"] and not cmp["loop_mass"]["avx512"]["same_verdict"]


def test_the_report_counts_only_the_current_codes_rows(monkeypatch):
    monkeypatch.setattr(bench, "code_stamp", lambda: "now")
    data = {"machine": "test", "rows": [_ident("scalar"), _ident("avx2", shift=0.01), _ident("avx512", stamp="old"),
                                        _loop("scalar", ["mass"]), _loop("avx2", [])]}
    text = bench.table(data)
    assert "4 of 5 stored rows of the current code" in text
    assert text.count("| identify_m20 |") == 2 and "avx512" not in text
    assert "largest CoR shift 0.20 of a half-interval" in text and "**verdict differs**" in text
