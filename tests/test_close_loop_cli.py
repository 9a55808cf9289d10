"""`lss close-loop` end to end on a rig measurement, and its errors."""
from __future__ import annotations

import json

import pytest

from lss_app.cli import main as lss


@pytest.fixture(scope="module")
def measurement(tmp_path_factory, fmu_file):
    out = tmp_path_factory.mktemp("rig") / "recovery"
    code = lss(["rig", "--set", "recovery", "--out", str(out), "--measurements", "20", "--workers", "1",
                "--lap-seconds", "0.6", "--no-progress", "--effects", "mass", "--effect-seed", "3"])
    assert code == 0
    return out / "m20"


def test_close_loop_writes_report_and_result(measurement, tmp_path, capsys):
    out = tmp_path / "loop"
    code = lss(["close-loop", str(measurement), "--model", "LW", "--out", str(out), "--free", "e_SW,e_RW",
                "--effects", "mass,sensor", "--base-evals", "5", "--max-evals", "5", "--fit-evals", "3", "--rounds", "1",
                "--refine-evals", "5", "--base-refine-evals", "10", "--profile-points", "0", "--no-progress"])
    assert code == 0, capsys.readouterr().err
    res = json.loads((out / "result.json").read_text())
    assert res["measurement"].endswith("m20") and res["model"] == "LW"
    rnd = res["rounds"][0]
    assert {r["effect"] for r in rnd["attribution"]["ranking"]} == {"mass", "sensor"}
    assert all(0.0 <= r["share"] <= 1.0 for r in rnd["attribution"]["ranking"])
    text = (out / "report.md").read_text()
    assert "Verdict" in text and "round1_attribution.png" in text
    assert (out / "round1_attribution.png").stat().st_size > 0
    assert (out / "round1_attribution.json").is_file()
    # the metadata declares nothing: the measurement folder holds no trace of the effect
    assert "effects" not in (measurement / "meta.json").read_text()


@pytest.mark.parametrize("protocol, number, lap", [("start-up", 1, 0.6),
                                                      pytest.param("stop", 20, 1.3, marks=pytest.mark.slow)])
def test_close_loop_follows_the_record_protocol(tmp_path_factory, fmu_file, capsys, protocol, number, lap):
    """A transient record (issue 18): the loop simulates what its metadata says
    (from rest, or the photocell then the stop), and reports the verdict with
    its evidence; the record's declared noise is used."""
    data = tmp_path_factory.mktemp(f"rig_{protocol}")
    assert lss(["rig", "--set", "recovery", "--out", str(data), "--measurements", str(number), "--workers", "1",
                "--lap-seconds", str(lap), "--no-progress", "--protocol", protocol]) == 0
    out = data / "loop"
    code = lss(["close-loop", str(data / f"m{number:02d}"), "--model", "LW", "--out", str(out), "--free", "e_SW,e_RW",
                "--effects", "mass,sensor", "--base-evals", "6", "--max-evals", "6", "--fit-evals", "3",
                "--rounds", "1", "--refine-evals", "5", "--base-refine-evals", "10", "--profile-points", "0",
                "--no-progress"])
    text = capsys.readouterr()
    assert code == 0, text.err
    assert f"{protocol} record" in text.out
    res = json.loads((out / "result.json").read_text())
    assert res["protocol"] == protocol
    rnd = res["rounds"][0]
    assert rnd["outcome"] in ("confirmed", "not in the catalogue", "nothing significant")
    assert rnd["noise"]["source"] == "declared"
    assert rnd["evidence"] is None or {"statistic", "p", "p_bonferroni", "holdout_gain"} <= set(rnd["evidence"])
    report = (out / "report.md").read_text()
    assert "### Evidence" in report and "Bonferroni" in report


@pytest.mark.parametrize("args, message", [
    (["--effects", "wheel_oor,flat_tyre"], "unknown flat_tyre"),
    (["--rounds", "0"], "--rounds 0"),
    (["--refine-evals", "-1"], "--refine-evals -1"),
    (["--model", "XX"], "unknown contact model"),
])
def test_close_loop_rejects_bad_options(measurement, tmp_path, capsys, args, message):
    base = ["close-loop", str(measurement), "--model", "LW", "--out", str(tmp_path / "o")]
    assert lss(base + args) == 2
    assert message in capsys.readouterr().err


def test_close_loop_rejects_a_base_result_of_another_model(measurement, tmp_path, capsys):
    bad = tmp_path / "result.json"
    bad.write_text(json.dumps({"model": "HC", "x": {}}))
    assert lss(["close-loop", str(measurement), "--model", "LW", "--out", str(tmp_path / "o"),
                "--base-result", str(bad)]) == 2
    assert "identified with model HC" in capsys.readouterr().err


def test_rig_options_reach_the_rig_before_any_positional(capsys):
    """`lss rig --set ...` (an option first) goes to the rig's own parser."""
    assert lss(["rig", "--set", "nonsense", "--out", "x"]) == 2
    assert "nonsense" in capsys.readouterr().err
