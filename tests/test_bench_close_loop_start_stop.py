"""benchmarks/bench_close_loop_start_stop.py: its records cover layouts 1-7 and
set each family's size in the rig's truth; its counting and resuming. (The
cases themselves run in the benchmark, not here: 300-650 CPU-s each.)"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

import bench_close_loop_start_stop as bench  # noqa: E402
from identification.loop.catalogue import CATALOGUE  # noqa: E402
from lss_fmu.rig import make_case  # noqa: E402


def test_the_records_cover_every_layout_and_other_sorters():
    cs = bench.cases("all", 7, families=["wheel_oor_2"], amp_index=[1])
    clean = [c for c in cs if c["kind"] == "clean"]
    det = [c for c in cs if c["kind"] == "effect"]
    assert len(clean) == bench.CLEAN_RECORDS >= 40 and len(det) == 7
    assert len({c["id"] for c in cs}) == len(cs)
    layouts = {make_case("recovery", bench.MEASUREMENTS[c["record"] % 7]).layout for c in det}
    assert layouts == {f"layout{k}" for k in range(1, 8)}
    kept = bench.cases("detect", 14, families=["mass"], layouts=[2, 7])
    assert {c["record"] % 7 + 1 for c in kept} == {2, 7} and len(kept) == 2 * 2 * len(bench.FAMILIES["mass"][1])


@pytest.mark.parametrize("family", list(bench.FAMILIES))
def test_each_family_is_set_to_its_amplitude_in_the_truth(family):
    eff = bench.EFFECT[family]
    for r in (0, 3):
        number = bench.MEASUREMENTS[r]
        drawn = make_case("recovery", number, bench.SEED0 + r, effects=[eff], effect_seed=1 + r,
                          protocol="start-stop", lap_seconds=bench.SECONDS).effects[eff]["parameters"]
        for a in bench.FAMILIES[family][1]:
            values = bench.size(family, a, drawn)
            case = make_case("recovery", number, bench.SEED0 + r, effects=[eff], effect_seed=1 + r,
                             protocol="start-stop", lap_seconds=bench.SECONDS, effect_values=values)
            got = case.effects[eff]["parameters"]
            assert all(got[k] == pytest.approx(v) for k, v in values.items())
            assert sorted(values) == case.effects[eff]["set"]
            unit = bench.FAMILIES[family][0]
            scale = {"um": 1e-6, "mm": 1e-3}.get(unit, 1.0)
            assert CATALOGUE[eff].amplitude(got) == pytest.approx(a * scale)


def test_the_report_counts_start_stop_rows_per_family(tmp_path, capsys):
    rows = []
    for r in range(5):
        rows.append({"id": f"ss_mass_a2_r{r:02d}", "kind": "effect", "family": "mass", "amplitude": 0.15,
                     "amp_index": 2, "record": r, "source": "rig start-stop", "found": ["mass"] if r < 4 else [],
                     "outcome": "confirmed" if r < 4 else "nothing significant", "cpu_s": 1.0})
    rows.append({"id": "ss_clean_r00", "kind": "clean", "source": "rig start-stop", "record": 0,
                 "found": ["track_bump"], "outcome": "confirmed", "cpu_s": 1.0})
    for row in rows:
        (tmp_path / f"{row['id']}.json").write_text(json.dumps(row))
    assert bench.main(["report", "--results", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "0.15: 4/5" in out and "1 of 1 with an effect confirmed" in out
    s = bench.summarise(rows, bench.FAMILIES)
    assert s["detection"]["mass"]["rows"][2]["found"] == 4 and s["clean"]["false_confirmations"] == ["ss_clean_r00"]


def test_a_run_resumes_and_records_a_case_that_fails(tmp_path, monkeypatch):
    ran = []

    def run_case(case):
        ran.append(case["id"])
        if case["record"] == 1:
            raise RuntimeError("the base diverged")
        return {**case, "found": [], "outcome": "nothing significant", "cpu_s": 1.0}
    monkeypatch.setattr(bench, "run_case", run_case)
    args = ["run", "--part", "clean", "--results", str(tmp_path), "--limit", "3"]
    assert bench.main(args) == 0 and ran == ["ss_clean_r00", "ss_clean_r01", "ss_clean_r02"]
    bad = json.loads((tmp_path / "ss_clean_r01.json").read_text())
    assert "the base diverged" in bad["error"] and bad["code_stamp"] == bench.code_stamp()
    ran.clear()
    assert bench.main(args) == 0 and ran == ["ss_clean_r03", "ss_clean_r04", "ss_clean_r05"]
    with pytest.raises(SystemExit, match="'ripple' is not one of"):
        bench.main(["run", "--families", "ripple", "--results", str(tmp_path)])
