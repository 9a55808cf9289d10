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


# small budgets: the base through the front door, then the loop
TINY = """
[identify]
free = ["e_SW", "e_RW"]
max_evals = 6
steady_evals = 6
refine_evals = 0
restarts = 0
shrink = false
first_window = 0.2
[close_loop]
max_evals = 6
fit_evals = 3
refine_evals = 5
base_refine_evals = 10
profile_points = 0
"""


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def test_close_loop_writes_report_and_result(measurement, tmp_path, capsys, tiny):
    out = tmp_path / "loop"
    code = lss(["close-loop", str(measurement), "--model", "LW", "--out", str(out), "--settings", str(tiny),
                "--effects", "mass,sensor", "--rounds", "1", "--no-progress"])
    assert code == 0, capsys.readouterr().err
    res = json.loads((out / "result.json").read_text())
    assert res["measurement"].endswith("m20") and res["model"] == "LW"
    # the base is the front door's identification with the file's [identify] settings, written beside
    base = json.loads((out / "base" / "result.json").read_text())
    assert base["settings"]["max_evals"] == 6 and base["settings"]["free"] == ["e_SW", "e_RW"]
    assert res["x_base"] == pytest.approx(base["x"])
    assert res["settings"]["close_loop"]["fit_evals"] == 3 and res["settings"]["identify"]["max_evals"] == 6
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
def test_close_loop_follows_the_record_protocol(tmp_path_factory, fmu_file, capsys, protocol, number, lap, tiny):
    """A transient record (issue 18): the loop simulates what its metadata says
    (from rest, or the photocell then the stop), and reports the verdict with
    its evidence; the record's declared noise is used."""
    data = tmp_path_factory.mktemp(f"rig_{protocol}")
    assert lss(["rig", "--set", "recovery", "--out", str(data), "--measurements", str(number), "--workers", "1",
                "--lap-seconds", str(lap), "--no-progress", "--protocol", protocol]) == 0
    out = data / "loop"
    code = lss(["close-loop", str(data / f"m{number:02d}"), "--model", "LW", "--out", str(out),
                "--settings", str(tiny), "--effects", "mass,sensor", "--rounds", "1", "--no-progress"])
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
    (["--workers", "0"], "--workers 0"),
    (["--model", "XX"], "unknown contact model"),
])
def test_close_loop_rejects_bad_options(measurement, tmp_path, capsys, args, message):
    base = ["close-loop", str(measurement), "--model", "LW", "--out", str(tmp_path / "o")]
    assert lss(base + args) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("text, fragments", [
    ("[close_loop]\nrefine_evals = -1\n", ["[close_loop]", "refine_evals = -1", "0 or more"]),
    ("[close_loop]\nbase_evals = 5\n", ["[close_loop]", "unknown key 'base_evals'", "candidates"]),
    ("[identify]\nmax_evals = 0\n", ["[identify]", "max_evals = 0"]),
    ("[loop]\nmax_evals = 5\n", ["unknown table [loop]", "[close_loop]"]),
])
def test_close_loop_refuses_a_bad_settings_file(measurement, tmp_path, capsys, text, fragments):
    """Nothing runs on a bad settings file: the error names the file, the table, the key and the value."""
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    assert lss(["close-loop", str(measurement), "--model", "LW", "--out", str(tmp_path / "o"),
                "--settings", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and all(f in err for f in fragments), err
    assert not (tmp_path / "o").exists()


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
