"""The recovery benchmark is a thin caller of the campaign: its rows come
from the campaign's results, compared with answer files the identification
never reads, and a row counts as a hit only with all three CoRs claimed and
within 0.03."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

from bench_recovery import doc_text, hit, main, summary  # noqa: E402


def test_a_small_recovery_table_from_the_campaign(tmp_path, fmu_file):
    settings = tmp_path / "small.toml"
    settings.write_text('[identify]\nwindow = 1.1\nfirst_window = 0.2\nmax_evals = 6\nrefine_evals = 0\n'
                        'restarts = 0\nshrink = false\nfree = ["e_SW", "e_RW"]\n')
    out = tmp_path / "recovery.json"
    args = ["--work", str(tmp_path / "work"), "--measurements", "20,21", "--repeats", "2", "--seconds", "1.1",
            "--settings", str(settings), "--workers", "2", "--json", str(out), "--no-progress"]
    assert main(args) == 0
    report = json.loads(out.read_text())
    assert [q["number"] for q in report["rows"]] == [20, 21]
    campaign = json.loads((tmp_path / "work" / "start-stop" / "campaign_k2" / "campaign.json").read_text())
    assert campaign["settings"] == report["settings"] and campaign["models"] == ["LW"]
    for q in report["rows"]:
        assert q["records"] == 2 and q["f_truth"] > 0 and q["ratio"] == pytest.approx(q["f"] / q["f_truth"])
        for s in ("e_JA", "e_SW", "e_RW", "e_JR"):
            assert q[s]["error"] == pytest.approx(q[s]["identified"] - q[s]["true"])
    # a resume reads the campaign's finished results: the same rows, nothing run again
    again = tmp_path / "again.json"
    assert main(args[:-3] + ["--json", str(again), "--no-progress"]) == 0
    assert [q["f"] for q in json.loads(again.read_text())["rows"]] == [q["f"] for q in report["rows"]]
    # a table of other settings is not grown into this one
    settings.write_text(settings.read_text().replace("max_evals = 6", "max_evals = 7"))
    with pytest.raises(SystemExit, match="holds rows of other settings"):
        main(args)


def test_a_hit_is_claimed_and_within():
    def row(err, ident=True):
        return {s: {"error": err, "identifiable": ident, "covers": True} for s in ("e_JA", "e_SW", "e_RW", "e_JR")} \
            | {"ratio": 1.0, "cpu_s": 1.0}
    assert hit(row(0.02), "e_RW") and not hit(row(0.04), "e_RW") and not hit(row(0.0, False), "e_RW")
    s = summary([row(0.02), row(0.0, False), row(0.04)])
    assert s["all_three_claimed_within"] == 1 and s["e_RW"]["within"] == 2 and s["e_RW"]["claimed_within"] == 1


def test_the_doc_table_shows_the_truth_and_counts_only_claimed_hits():
    def cor(true, err, ident=True):
        return {"true": true, "error": err, "identifiable": ident, "covers": abs(err) < 0.02,
                "interval": {"sd": 0.01}}

    def row(n, err, ident=True):
        return {"number": n, "layout": "layout2", "ratio": 1.0, "cpu_s": 10.0, "window_s": 2.5, "windows": [2.5],
                "e_JA": cor(0.31, 0.001), "e_SW": cor(0.72, -0.002), "e_RW": cor(0.45, err, ident),
                "e_JR": cor(0.5, 0.2, False)}
    rows = [row(5, 0.01), row(6, 0.01, False), row(7, 0.05)]
    text = doc_text({"summary": summary(rows), "rows": rows, "protocol": "start-stop", "repeats": 3,
                     "rig_seed": 7}, "x.json")
    assert "**1 of 3**" in text and "rig seed 7" in text
    assert text.count("0.31/0.72/0.45") == 3 and "+0.010 n.i." in text
