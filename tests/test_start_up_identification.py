"""Identification from a start-up record on a layout other than 7 (issue 17).

The rig's start-up record of a recovery measurement (the chain parked, the
drive's set point stepped at the start command, the transducer cart where
the rig parked it): with the layout-dependent variables at their true values
the four CoRs are free, Complex-RF finds the basin and Levenberg-Marquardt
its bottom. The start-up (paper's objective): f within 2x the noise floor
f(truth) and an interval for every CoR. The start-stop (likelihood): e_JA,
e_SW and e_RW within 3 standard deviations of the truth, e_JA and e_SW within
0.03.
"""
from __future__ import annotations

import numpy as np
import pytest

from identification.pipeline.identify import identify
from identification.objective.problem import drive_known, from_measurement
from lss_fmu.design import CORS
from lss_fmu.rig import load_truth, true_design_values

WINDOW = 1.5   # s: long enough for the first wave through the chain, short for a test


@pytest.fixture(scope="module", params=[19], ids=["m19-layout6"])
def record(request, rig_record):
    return rig_record(request.param, "start-up", WINDOW + 0.2)


def truth_values(meas) -> dict:
    return true_design_values(load_truth(meas))


def test_a_start_up_identification_reaches_the_noise_floor_with_intervals(record):
    """Item 3 and 4 of issue 17 on a layout other than 7. Which CoR values it
    lands on is measured in benchmarks/bench_recovery.py: at the floor, start-up
    records leave several CoR vectors within the noise (docs/identification.md),
    so the values themselves are not asserted here."""
    truth = truth_values(record)
    p = drive_known(from_measurement(record, "LW", window=WINDOW, tare=True), truth)
    xt = np.array([truth[n] for n in CORS])
    f_truth = p(xt)
    try:
        res = identify(p, max_evals=120, refine_evals=40, uncertainty=True, seed=0, progress=False)
    finally:
        p.sim.close()
    assert res.f <= 2.0 * f_truth, (res.f, f_truth)
    assert res.f <= res.f0
    assert [iv.name for iv in res.intervals] == list(CORS)
    for iv, x in zip(res.intervals, res.x):
        assert iv.lower <= x <= iv.upper and iv.method == "jacobian", iv
    jr = res.intervals[CORS.index("contact.e_JR")]
    assert not jr.identifiable or abs(jr.value - truth["contact.e_JR"]) <= 0.05, jr
    d = res.to_dict()
    assert set(d["interval"]) == {"e_JA", "e_JR", "e_SW", "e_RW"} and d["protocol"]["name"] == "start-up"


@pytest.fixture(scope="module")
def start_stop(rig_record):
    return rig_record(19, "start-stop", 2.2)


@pytest.mark.slow   # make test: the front door on a start-stop, tests/test_front_door.py
def test_a_start_stop_identification_finds_the_cors(start_stop):
    """The protocol and the objective docs/identification.md found best: a
    start-stop (layout 6, the transducer where the rig parked it), the
    likelihood objective, the CoRs free with the drive known. The estimate
    is as good as the record allows: each of e_JA, e_SW, e_RW within 3 of
    its standard deviations of the truth (the Jacobian's, which at the
    truth is the Cramér-Rao bound of benchmarks/bench_information.py), and
    the two the record determines best (sd ~0.01) within 0.03."""
    truth = truth_values(start_stop)
    p = drive_known(from_measurement(start_stop, "LW", window=2.0, tare=True, objective="likelihood"), truth)
    xt = np.array([truth[n] for n in CORS])
    f_truth = p(xt)
    try:
        res = identify(p, max_evals=120, refine_evals=40, uncertainty=True, seed=0, progress=False)
    finally:
        p.sim.close()
    assert res.f <= f_truth + 10.0 / len(p.times), (res.f, f_truth)   # within 10 chi^2 units of the truth
    iv = {i.name: i for i in res.intervals}
    for name in ("contact.e_JA", "contact.e_SW", "contact.e_RW"):
        err = dict(zip(CORS, res.x))[name] - truth[name]
        assert iv[name].identifiable and abs(err) <= 3.0 * iv[name].sd, (name, err, iv[name])
    for name in ("contact.e_JA", "contact.e_SW"):
        assert abs(dict(zip(CORS, res.x))[name] - truth[name]) <= 0.03, (name, res.x, truth)
