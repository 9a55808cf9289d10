"""The side-by-side table of two identification profiles (benchmarks/profile_identification.py --ab):
the stages in CPU-s or in simulated record-seconds, and the totals over the measurements both have."""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

from profile_identification import ab_table  # noqa: E402


def _row(n, cpu, stages, f=21.0, err=0.001):
    return {"measurement": n, "layout": "layout7", "cpu_s": cpu, "f": f,
            "cor_error": {"e_JA": err, "e_SW": -err, "e_RW": 0.0, "e_JR": 0.3},
            "stages": [{"stage": f"setup / run / {k}", "cpu_s": c, "simulated_record_s": r}
                       for k, (c, r) in stages.items()]}


BEFORE = {"rows": [_row(1, 100.0, {"growing windows": (60.0, 600.0), "whole record / intervals": (10.0, 200.0)}),
                   _row(2, 50.0, {"growing windows": (40.0, 400.0)})]}
AFTER = {"rows": [_row(1, 80.0, {"growing windows": (60.0, 600.0), "whole record / intervals": (0.5, 5.0)}),
                  _row(3, 10.0, {"growing windows": (9.0, 90.0)})]}


def test_record_seconds_with_the_intervals_and_the_total():
    lines = ab_table(BEFORE, AFTER, "record-s").splitlines()
    assert "simulated record-s" in lines[0] and "intervals" in lines[0]
    assert all(line.count("|") == lines[0].count("|") for line in lines)
    row = lines[2]
    assert "100 -> 80 (0.80)" in row and "800 -> 605 (0.76)" in row and "200 -> 5" in row
    assert lines[-1].startswith("| all 1 |")   # measurement 3 has no before, 2 no after: neither counts


def test_cpu_seconds_by_default():
    lines = ab_table(BEFORE, AFTER).splitlines()
    assert "simulated" not in lines[0] and "intervals" not in lines[0]
    assert "| 60 -> 60 |" in lines[2] and len(lines) == 3
