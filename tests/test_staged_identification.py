"""Staged identification with the paper's ten design variables free (issue 17,
identification.staged): the layout-dependent variables by Levenberg-Marquardt,
the complex on the CoRs, Levenberg-Marquardt on all ten, and the complex over
everything when that ends above the declared noise.

The record: the rig's start-stop of a layout-1 measurement, the transducer
where the rig parked it, nothing of the truth given to the identification
(the drive's values start at the nominal ones of meta.json). What must hold:
the fit reaches the noise (f within 10 chi^2 units of f at the truth) and
e_JA and e_SW, the CoRs this record determines to about 0.01, are within
0.03 of the truth with intervals holding them.
"""
from __future__ import annotations

import numpy as np
import pytest

from identification.problem import from_measurement
from identification.staged import identify_staged
from identification.uncertainty import at_noise
from lss_fmu.rig import load_truth, true_design_values

WINDOW = 2.0


@pytest.fixture(scope="module")
def start_stop_layout1(rig_record):
    return rig_record(1, "start-stop", WINDOW + 0.2)


@pytest.mark.slow
def test_ten_free_staged_reaches_the_noise_and_the_cors(start_stop_layout1):
    meas = start_stop_layout1
    truth = true_design_values(load_truth(meas))
    p = from_measurement(meas, "LW", window=WINDOW, tare=True, objective="likelihood")
    assert len(p.free) == 10
    xt = np.array([truth[n] for n in p.free])
    try:
        f_truth = p(xt)
        res = identify_staged(p, max_evals=120, refine_evals=200, uncertainty=True, seed=0, progress=False)
    finally:
        p.sim.close()
    assert at_noise(p, f_truth)
    assert res.f <= f_truth + 10.0 / len(p.times), (res.f, f_truth, res.message)
    assert res.presolved["method"] == "levenberg-marquardt" and res.refined is not None
    vals = p.values(res.x)
    iv = {i.name: i for i in res.intervals}
    for name in ("contact.e_JA", "contact.e_SW"):
        assert abs(vals[name] - truth[name]) <= 0.03, (name, vals[name], truth[name])
        assert iv[name].identifiable and iv[name].lower <= truth[name] <= iv[name].upper, (name, iv[name])
    assert set(res.to_dict()["interval"]) >= {"e_JA", "e_JR", "e_SW", "e_RW"}


def test_staged_refuses_what_it_cannot_do(start_stop_layout1):
    p = from_measurement(start_stop_layout1, "LW", window=0.5, objective="statistics")
    try:
        with pytest.raises(ValueError, match="statistics objective is not a sum of squares"):
            identify_staged(p, max_evals=10, progress=False)
    finally:
        p.sim.close()
    p = from_measurement(start_stop_layout1, "LW", window=0.5, objective="likelihood")
    try:
        with pytest.raises(ValueError, match="stage_evals = -1 must be 0 or more"):
            identify_staged(p, stage_evals=-1, progress=False)
    finally:
        p.sim.close()


def test_at_noise_is_the_chi2_test(start_stop_layout1):
    """at_noise: 7 channels, n samples: f at most 7 (1.03) + 5 sqrt(14 / n)."""
    p = from_measurement(start_stop_layout1, "LW", window=1.0, objective="likelihood")
    try:
        n = len(p.times)
        edge = 7 * 1.03 + 5 * np.sqrt(14.0 / n)
        assert at_noise(p, edge - 1e-9) and not at_noise(p, edge + 1e-9)
        assert at_noise(from_measurement(start_stop_layout1, "LW", window=1.0, sim=p.sim), 1.0) is None
    finally:
        p.sim.close()
