"""benchmarks/bench_close_loop_rates.py: the code stamp of each case, the rerun of stale ones, the report's count."""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

import bench_close_loop_rates as bench  # noqa: E402


def test_code_stamp_is_a_short_hash_and_stable():
    a, b = bench.code_stamp(), bench.code_stamp()
    assert a == b and re.fullmatch(r"[0-9a-f]{12}", a)


def test_code_stamp_follows_the_budget(monkeypatch):
    before = bench.code_stamp()
    monkeypatch.setitem(bench.BUDGET, "base_evals", bench.BUDGET["base_evals"] + 1)
    assert bench.code_stamp() != before


@pytest.fixture
def fake_run(monkeypatch):
    ran = []

    def run_case(case, budget):
        ran.append(case["id"])
        return {**case, "found": [], "outcome": "nothing significant", "verdict": "", "cpu_s": 1.0, "wall_s": 1.0}

    monkeypatch.setattr(bench, "run_case", run_case)
    return ran


def _store(folder: Path, case_id: str, stamp):
    case = {"id": case_id, "kind": "clean", "source": "synthetic", "record": 0, "found": [],
            "outcome": "nothing significant"}
    if stamp is not None:
        case["code_stamp"] = stamp
    (folder / f"{case_id}.json").write_text(json.dumps(case))


def test_stale_cases_rerun_only_when_asked(tmp_path, fake_run):
    now = bench.code_stamp()
    _store(tmp_path, "clean_syn_00", None)        # a row from before the stamps
    _store(tmp_path, "clean_syn_01", "0123456789ab")
    _store(tmp_path, "clean_syn_02", now)
    ids = "clean_syn_00,clean_syn_01,clean_syn_02,clean_syn_03"
    bench.main(["run", "--part", "clean", "--ids", ids, "--results", str(tmp_path)])
    assert fake_run == ["clean_syn_03"]            # resume: only the missing case
    fake_run.clear()
    bench.main(["run", "--part", "clean", "--ids", ids, "--results", str(tmp_path), "--stale"])
    assert fake_run == ["clean_syn_00", "clean_syn_01"]
    rows = bench.load_results(tmp_path)
    assert all(r["code_stamp"] == now for r in rows) and all("commit" in r for r in rows if r["id"] != "clean_syn_02")
    code = bench.code_of(rows, now)
    assert code["of_current"] == 4 and code["rows"] == 4 and code["other"] == []


def test_report_names_the_rows_of_other_code(tmp_path, capsys):
    _store(tmp_path, "clean_syn_00", "0123456789ab")
    _store(tmp_path, "clean_syn_01", bench.code_stamp())
    code = bench.code_of(bench.load_results(tmp_path), bench.code_stamp())
    assert code["of_current"] == 1 and code["other"] == ["clean_syn_00"]
    bench.main(["report", "--results", str(tmp_path)])
    out = capsys.readouterr().out
    assert "1 of 2 rows of the current code" in out and "the other 1 are from earlier code" in out


def test_report_current_only_counts_the_current_rows(tmp_path, capsys):
    _store(tmp_path, "clean_syn_00", "0123456789ab")
    _store(tmp_path, "clean_syn_01", bench.code_stamp())
    _store(tmp_path, "clean_syn_02", bench.code_stamp())
    bench.main(["report", "--results", str(tmp_path), "--current-only"])
    out = capsys.readouterr().out
    assert "2 of 3 rows of the current code" in out and "left out of the counts" in out and '"records": 2' in out
