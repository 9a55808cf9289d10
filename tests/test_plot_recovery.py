"""The recovery figure (benchmarks/plot_recovery.py): drawn from a result file, a
malformed one refused by name."""
from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

from plot_recovery import hit, main  # noqa: E402


def _row(n, errors, identifiable=True):
    row = {"number": n}
    for c, e in zip(("e_JA", "e_SW", "e_RW"), errors):
        row[c] = {"error": e, "identifiable": identifiable,
                  "interval": {"sd": 0.01} if identifiable else {"sd": None}}
    return row


def test_a_hit_needs_all_three_claimed_and_within_the_tolerance():
    assert hit(_row(1, (0.0, -0.03, 0.029)))
    assert not hit(_row(2, (0.0, 0.0, 0.031)))
    assert not hit(_row(3, (0.0, 0.0, 0.01), identifiable=False))   # a value reported unidentifiable is no hit


def test_the_figure_of_one_campaign_table(tmp_path):
    src = tmp_path / "r.json"
    src.write_text(json.dumps({"protocol": "start-stop", "repeats": 3, "rows": [_row(1, (0.01, 0.0, -0.02))]}))
    out = tmp_path / "fig.png"
    assert main([str(src), "--out", str(out)]) == 0 and out.stat().st_size > 10_000


def test_the_figure_is_drawn_from_a_result_file(tmp_path):
    src = tmp_path / "r.json"
    src.write_text(json.dumps({"protocols": {"start-stop": {"rows": [_row(1, (0.01, 0.0, -0.02)),
                                                                      _row(8, (0.3, -0.5, 0.1), False)]}}}))
    out = tmp_path / "fig.png"
    assert main([str(src), "--out", str(out)]) == 0
    assert out.stat().st_size > 10_000


def test_a_file_that_is_not_a_result_is_named(tmp_path, capsys):
    src = tmp_path / "bad.json"
    src.write_text("{\"rows\": []}")
    assert main([str(src), "--out", str(tmp_path / "fig.png")]) == 2
    assert "bad.json: not a bench_recovery result file" in capsys.readouterr().err
