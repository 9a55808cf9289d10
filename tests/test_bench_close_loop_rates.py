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


def _effect(fam: str, ia: int, found: list, outcome: str = "confirmed", k: int = 0) -> dict:
    return {"id": f"{fam}_{ia}_{k}", "kind": "effect", "family": fam, "amp_index": ia, "found": found,
            "outcome": outcome, "cpu_s": 2.0}


def test_summarise_counts_hits_wrong_effects_and_the_90_percent_amplitude():
    """The rates: a hit is the family's effect confirmed first (the sensor families count 'sensor'),
    another effect confirmed is a wrong one, an errored row counts nowhere; the smallest amplitude
    found in >= 90 % needs at least 5 records; clean rows with anything confirmed are false alarms."""
    rows = [{"id": "c0", "kind": "clean", "source": "synthetic", "found": [], "outcome": "nothing significant",
             "cpu_s": 1.0},
            {"id": "c1", "kind": "clean", "source": "rig", "found": ["mass"], "outcome": "confirmed",
             "protocol": "start-stop", "layout": 1, "cpu_s": 3.0},
            {"id": "c2", "kind": "clean", "source": "rig", "found": [], "error": "failed", "cpu_s": 1.0}]
    # mass, amplitude index 1: 5 records, 5 hits; index 0: 4 of 4 (too few to count); index 2: 4 of 5
    rows += [_effect("mass", 1, ["mass"], k=k) for k in range(5)]
    rows += [_effect("mass", 0, ["mass"], k=k) for k in range(4)]
    rows += [_effect("mass", 2, ["mass"], k=k) for k in range(4)] + [_effect("mass", 2, ["motor_ripple"], k=4)]
    rows += [_effect("sensor_gain", 3, ["sensor"], k=k) for k in range(5)]
    rows += [_effect("sensor_gain", 2, [], "nothing significant", k=k) for k in range(5)]
    rows += [{"id": "o0", "kind": "ooc", "artefact": "crosstalk", "found": [], "outcome": "not in the catalogue",
              "cpu_s": 1.0}]
    s = bench.summarise(rows)
    assert s["clean"]["records"] == 2 and s["clean"]["false_confirmations"] == ["c1"]
    assert s["clean"]["by_source"] == {"synthetic": 1, "rig": 1} and s["errors"] == ["c2"]
    mass = {r["amplitude"]: r for r in s["detection"]["mass"]["rows"]}
    amps = bench.FAMILIES["mass"][1]
    assert mass[amps[1]]["rate"] == 1.0 and mass[amps[0]]["records"] == 4
    assert mass[amps[2]]["found"] == 4 and mass[amps[2]]["wrong_effect"] == 1 and mass[amps[2]]["rate"] == 0.8
    assert s["detection"]["mass"]["smallest_90"] == amps[1]          # not amps[0]: only 4 records there
    gain = s["detection"]["sensor_gain"]
    assert gain["smallest_90"] == bench.FAMILIES["sensor_gain"][1][3]
    assert {r["amplitude"]: r["outcomes"]["nothing significant"] for r in gain["rows"]}[
        bench.FAMILIES["sensor_gain"][1][2]] == 5
    assert s["out_of_catalogue"]["crosstalk"] == {"records": 1, "not_in_catalogue": 1, "confirmed": 0, "nothing": 0}
    assert s["detection"]["track_bump"]["smallest_90"] is None       # no record: no threshold
    assert s["cpu_s"]["total"] == pytest.approx(sum(r["cpu_s"] for r in rows))


def test_rates_carry_their_exact_interval():
    """Each rate with its exact (Clopper-Pearson) 95 % interval: 5 of 5 bounds the rate only above 48 %,
    20 of 20 above 83 %; the threshold's lower end and the clean records' false-alarm bound are reported."""
    assert bench.rate_interval(5, 5)[0] == pytest.approx(0.4782, abs=1e-4)
    assert bench.rate_interval(20, 20)[0] == pytest.approx(0.8316, abs=1e-4)
    lo, hi = bench.rate_interval(0, 40)
    assert lo == 0.0 and hi == pytest.approx(0.0881, abs=1e-4)
    assert bench.rate_interval(0, 0) == [0.0, 1.0]
    rows = [_effect("mass", 1, ["mass"], k=k) for k in range(20)]
    rows += [{"id": f"c{k}", "kind": "clean", "source": "synthetic", "found": [], "outcome": "nothing significant",
              "cpu_s": 1.0} for k in range(40)]
    s = bench.summarise(rows)
    mass = s["detection"]["mass"]
    assert mass["smallest_90"] == bench.FAMILIES["mass"][1][1]
    assert mass["smallest_90_lower"] == pytest.approx(0.8316, abs=1e-4)
    assert s["clean"]["false_rate_upper"] == pytest.approx(0.0881, abs=1e-4)
    text = bench.table(s)
    assert "83-100 %" in text and "below 9 %" in text
