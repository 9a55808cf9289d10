"""A record that turns chaotic, identified on a shorter window (issue 17,
identification.windowing).

A start-stop of layout 5, the drive known, the four CoRs free,
the likelihood objective: on its first 1.5 s the steering wheels already
bounce in the guide once the drive brakes, and the roughness check calls the
CoRs not smooth (benchmarks/bench_information.py). identify_windowed must see
that, cut the record, and find e_JA and e_SW within 0.03 of the truth on the
shorter window. The CoRs start in the middle of their range; only the
drive's settings are given (as the manufacturer knows them).
"""
from __future__ import annotations

import numpy as np
import pytest

from identification.identify import identify
from identification.problem import drive_known, from_measurement
from identification.windowing import identify_windowed, troubles
from lss_fmu.rig import load_truth, true_design_values


@pytest.fixture(scope="module")
def start_stop_layout5(rig_record):
    return rig_record(13, "start-stop", 1.7)


@pytest.mark.slow
def test_a_chaotic_window_is_cut_and_the_cors_found(start_stop_layout5):
    meas = start_stop_layout5
    truth = true_design_values(load_truth(meas))
    p = drive_known(from_measurement(meas, "LW", window=1.5, tare=True, objective="likelihood"), truth)
    try:
        res = identify_windowed(p, identify, max_evals=80, refine_evals=40, uncertainty=True, seed=0,
                                progress=False)
    finally:
        p.sim.close()
    assert res.windows[0]["window_s"] == pytest.approx(1.5, abs=0.01)
    # the window the ladder ends on is smooth (whether 1.5 s already was follows the rounding)
    assert troubles(res) == [], res.windows
    vals = res.problem.values(res.x)
    for name in ("contact.e_JA", "contact.e_SW"):
        assert abs(vals[name] - truth[name]) <= 0.03, (name, vals[name], truth[name], res.windows)
    assert res.to_dict()["window_s"] == pytest.approx(res.windows[-1]["window_s"])
    assert np.isfinite(res.f)
