"""Identification over a growing window (issue 17, identification.identify_grown):
the complex on the record's first 0.3 s, Levenberg-Marquardt carried along
windows growing to the whole record, then the refinement and the intervals.

The accuracy case: the rig's start-stop of a layout-6 measurement, the
paper's ten variables free, nothing of the truth given (the drive's values
start at the nominal ones of meta.json, the CoRs at 0.55). What must hold:
the fit reaches the noise (f within 10 chi^2 units of f at the truth) and
e_JA, the CoR this record determines best, is within 0.03 of the truth with
an interval holding it. The other cases check the plumbing cheaply: the
step back to a shorter window starts from the grown trail's own point, and
what the pipeline cannot do is refused with a message.
"""
from __future__ import annotations

import numpy as np
import pytest

import identification.identify_grown as ig
from identification.identify_grown import identify_grown
from identification.problem import drive_known, from_measurement
from identification.staged import run
from identification.uncertainty import at_noise
from lss_fmu.rig import load_truth, true_design_values

WINDOW = 1.5


@pytest.fixture(scope="module")
def start_stop_layout6(rig_record):
    return rig_record(19, "start-stop", WINDOW + 0.2)


def test_ten_free_grown_reaches_the_noise_and_e_JA(start_stop_layout6):
    meas = start_stop_layout6
    truth = true_design_values(load_truth(meas))
    p = from_measurement(meas, "LW", window=WINDOW, tare=True, objective="likelihood")
    assert len(p.free) == 10
    try:
        f_truth = p(np.array([truth[n] for n in p.free]))
        res = identify_grown(p, max_evals=150, refine_evals=60, uncertainty=True, seed=0)
    finally:
        p.sim.close()
    assert at_noise(p, f_truth)
    assert res.f <= f_truth + 10.0 / len(p.times), (res.f, f_truth, res.message)
    vals = p.values(res.x)
    iv = {i.name: i for i in res.intervals}
    e = "contact.e_JA"
    assert abs(vals[e] - truth[e]) <= 0.03, (vals[e], truth[e], res.message)
    assert iv[e].identifiable and iv[e].lower <= truth[e] <= iv[e].upper, iv[e]
    d = res.to_dict()
    assert [w["window_s"] for w in d["grown"]][0] == pytest.approx(0.3) and "x" not in d["grown"][0]
    assert d["grown"][-1]["window_s"] == pytest.approx(WINDOW, abs=0.01)
    assert set(d["interval"]) >= {"e_JA", "e_JR", "e_SW", "e_RW"}


def test_a_shorter_window_starts_from_the_grown_point_at_its_length(start_stop_layout6, monkeypatch):
    """While the window is in trouble (forced here: the check itself is
    windowing's), the next shorter window of the ladder is refined from the
    trail's point at the longest grown window not beyond it, not from the
    full window's optimum."""
    meas = start_stop_layout6
    truth = true_design_values(load_truth(meas))
    p = drive_known(from_measurement(meas, "LW", window=WINDOW, tare=True, objective="likelihood"), truth)
    monkeypatch.setattr(ig, "troubles", lambda res: ["forced"] if res.problem.times[-1] > 1.1 else [])
    try:
        res = run(p, False, True, True, max_evals=30, refine_evals=5, uncertainty=True, seed=1)
    finally:
        p.sim.close()
    tried = res.windows
    assert [round(t["window_s"], 1) for t in tried] == [WINDOW, 1.2, 1.0]   # 1.5 and 1.2 forced, 1.0 not
    grown = [g["window_s"] for g in res.grown]
    for t in tried[1:]:
        assert t["from_window_s"] in grown and t["from_window_s"] <= t["window_s"] + 1e-9
    assert res.problem.times[-1] <= 1.0 + 1e-9 and "; windows " in res.message
    assert res.to_dict()["window_s"] == pytest.approx(1.0, abs=0.01)


def test_grown_refuses_what_it_cannot_do(start_stop_layout6):
    p = from_measurement(start_stop_layout6, "LW", window=0.5, objective="statistics")
    try:
        with pytest.raises(ValueError, match="statistics objective is not a sum of squares"):
            identify_grown(p, max_evals=10)
    finally:
        p.sim.close()
    p = from_measurement(start_stop_layout6, "LW", window=0.5, objective="likelihood")
    try:
        with pytest.raises(ValueError, match="max_evals = 0 must be at least 1"):
            identify_grown(p, max_evals=0)
        with pytest.raises(ValueError, match="needs uncertainty=True"):
            identify_grown(p, max_evals=10, shrink=True)
        with pytest.raises(ValueError, match="staged or grown, not both"):
            run(p, True, False, True, max_evals=10)
    finally:
        p.sim.close()
