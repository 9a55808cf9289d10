"""Several start-stops of one sorter identified together (issue 17):
`lss rig --repeat K` parks the chain elsewhere and draws the sensor anew,
identification.objective.joint.JointProblem shares the design variables and keeps
each record's trigger point."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from identification.pipeline.identify import identify
from identification.objective.joint import JointProblem
from identification.objective.problem import drive_known, from_measurement
from identification.objective.uncertainty import intervals
from lss_fmu.design import CORS, DESIGN, TRIGGER
from lss_fmu.rig import load_truth, make_case, true_design_values

NUMBER, WINDOW = 19, 2.0


@pytest.fixture(scope="module")
def records(rig_record):
    return [rig_record(NUMBER, "start-stop", WINDOW + 0.2, repeat=k) for k in range(2)]


def _problems(records, cors_only: bool):
    out = []
    for rec in records:
        p = from_measurement(rec, "LW", window=WINDOW, tare=True, objective="likelihood")
        if cors_only:
            p = drive_known(p, true_design_values(load_truth(rec)))
        out.append(p)
    return out


def test_a_repeat_is_the_same_sorter_parked_elsewhere(records):
    a, b = (true_design_values(load_truth(r)) for r in records)
    assert {k: v for k, v in a.items() if k != TRIGGER} == {k: v for k, v in b.items() if k != TRIGGER}
    assert abs(a[TRIGGER] - b[TRIGGER]) > 1.0
    assert records[1].id == f"recovery-m{NUMBER:02d}-r1" and "--repeat 1" in records[1].meta["source"]
    assert not np.allclose(records[0].forces.to_numpy(), records[1].forces.to_numpy())
    with pytest.raises(ValueError, match="only a protocol that starts from rest.*'steady'"):
        make_case("recovery", NUMBER, protocol="steady", repeat=1)
    with pytest.raises(ValueError, match="repeat -1"):
        make_case("recovery", NUMBER, protocol="start-stop", repeat=-1)


def test_the_joint_problem_is_the_records_side_by_side(records):
    parts = _problems(records, cors_only=False)
    jp = JointProblem(parts)
    assert jp.free == tuple(DESIGN) + (f"{TRIGGER}@1",)
    x = jp.x0_vector()
    assert x[-1] == parts[1].x0[TRIGGER] and x[DESIGN.index(TRIGGER)] == parts[0].x0[TRIGGER]
    assert jp.bounds[f"{TRIGGER}@1"] == parts[1].bounds[TRIGGER]
    x0, x1 = jp.part_x(0, x), jp.part_x(1, x)
    assert jp(x) == pytest.approx(parts[0](x0) + parts[1](x1), rel=1e-12)
    assert jp.simulate(x).shape == (len(parts[0].times), 14) and len(jp.noise) == 14
    assert np.sum(jp.channel_errors(x) ** 2) == pytest.approx(jp(x), rel=1e-12)
    assert jp.values(x)[f"{TRIGGER}@1"] == x1[DESIGN.index(TRIGGER)]
    short = from_measurement(records[1], "LW", window=1.0, tare=True, objective="likelihood")
    with pytest.raises(ValueError, match="same window"):
        JointProblem([parts[0], short])
    with pytest.raises(ValueError, match="objective"):
        JointProblem([parts[0], dataclasses.replace(parts[1], objective="pointwise", noise=None)])
    bad = x.copy()
    bad[DESIGN.index("drive.Kp")] = -1e9          # the FMU refuses it: a failed record fails the joint value
    assert jp(bad) == 2 * parts[0].bad_value


@pytest.mark.slow
def test_two_records_identify_the_cors_closer_than_one(records):
    """The drive known, the CoRs free: each of e_JA, e_SW, e_RW within 3 of its
    standard deviations of the truth, and those standard deviations below
    0.85 of one record's (1 / sqrt 2 = 0.71 for two records alike)."""
    parts = _problems(records, cors_only=True)
    jp = JointProblem(parts)
    truth = true_design_values(load_truth(records[0]))
    xt = np.array([truth[n] for n in CORS])
    try:
        one = {iv.name: iv for iv in intervals(parts[0], xt)}
        res = identify(jp, max_evals=120, refine_evals=40, uncertainty=True, seed=0, progress=False)
    finally:
        jp.close()
    assert res.f <= jp(xt) + 10.0 / len(parts[0].times)
    both = {iv.name: iv for iv in res.intervals}
    for name in ("contact.e_JA", "contact.e_SW", "contact.e_RW"):
        err = dict(zip(CORS, res.x))[name] - truth[name]
        assert abs(err) <= 3.0 * both[name].sd, (name, err, both[name])
        assert both[name].sd < 0.85 * one[name].sd, (name, both[name].sd, one[name].sd)
    assert res.to_dict()["measurement"] == f"recovery-m{NUMBER:02d} (+1 records)"


def test_lss_identify_takes_further_records(records, tmp_path):
    """`lss identify FIRST SECOND`: one result for both records, the second's
    trigger point its own variable, the settings used written beside it."""
    import json
    import subprocess
    import sys
    settings = tmp_path / "quick.toml"
    settings.write_text('[identify]\nwindow = 0.4\nfirst_window = 0.4\nfree = ["e_JA", "e_SW", "s_M"]\nmax_evals = 8\n'
                        'refine_evals = 0\nrestarts = 0\nshrink = false\nstart = "complex"\n')
    out = tmp_path / "joint"
    cp = subprocess.run([sys.executable, "-m", "lss_app.cli", "identify", str(records[0].path),
                         str(records[1].path), "--model", "LW", "--out", str(out), "--settings", str(settings),
                         "--no-progress"], capture_output=True, text=True, timeout=600)
    assert cp.returncode == 0, cp.stderr
    res = json.loads((out / "result.json").read_text())
    assert res["free"] == ["contact.e_JA", "contact.e_SW", TRIGGER, f"{TRIGGER}@1"]
    assert "s_M@1" in res["values"] and res["measurement"].endswith("(+1 records)")
    assert res["method"] == "grown" and res["settings"]["max_evals"] == 8 and res["settings"]["window"] == 0.4
    assert res["settings"]["free"] == ["e_JA", "e_SW", "s_M"] and len(res["records"]) == 2
    assert (out / "forces.png").is_file()
