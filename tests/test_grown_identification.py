"""Identification over a growing window (issue 17, identification.pipeline.identify_grown):
the complex on the record's first 0.3 s, Levenberg-Marquardt carried along
windows growing to the whole record, then the refinement and the intervals.

On the rig's start-stop of a layout-1 measurement: what the first window
cannot see is put back to its start value, the step back to a shorter
window starts from the grown trail's own point, and what the pipeline cannot
do is refused with a message. What it recovers with the ten variables free
costs 3-6 CPU-minutes a record and is measured in benchmarks
(bench_recovery.py --grown, docs/identification.md), not here: at a test's
budget (150 evaluations on 1.5 s of that record) the first window stopped at 1.85
times the noise and the whole record at 5 times f(truth).
"""
from __future__ import annotations

import numpy as np
import pytest

import identification.pipeline.growing as growing
import identification.pipeline.windowing as windowing
from identification.pipeline.identify_grown import identify_grown
from identification.pipeline.refine import Refined
from identification.objective.problem import drive_known, from_measurement
from lss_fmu.rig import load_truth, true_design_values

WINDOW = 1.5


@pytest.fixture(scope="module")
def start_stop_layout1(rig_record):
    return rig_record(1, "start-stop", WINDOW + 0.2)


def test_what_the_first_window_cannot_see_goes_back_to_its_start(start_stop_layout1):
    """On a start-stop's first 0.3 s the motors are saturated: v_ref, K_P and
    K_I move nothing, so the complex leaves them wherever its last point put
    them (K_P 1240 above the truth on a layout-6 record). growing._reset_unseen
    puts exactly those back to their start values (meta.json's nominal ones)
    and keeps everything the window does see (the CoRs, the pretension, the
    trigger point)."""
    from identification.pipeline.growing import _reset_unseen
    from identification.objective.problem import tared
    from identification.pipeline.windowing import truncated
    meas = start_stop_layout1
    truth = true_design_values(load_truth(meas))
    p = from_measurement(meas, "LW", window=WINDOW, tare=True, objective="likelihood")
    try:
        q = truncated(p, 0.3)
        w = 1.0 / p.noise ** 2
        x = np.array([truth[n] for n in p.free])
        lo, hi = np.array(p.bounds_array).T
        far = {"drive.Kp": 0.9, "drive.Ki": 0.9, "drive.v_ref": 0.1, "contact.e_SW": 0.8}
        for name, share in far.items():   # a complex's last point: far off in these
            i = p.free.index(name)
            x[i] = lo[i] + share * (hi[i] - lo[i])
        S = float(np.sum(tared(q.samples - q.simulate(x), q.tare) ** 2 * w))
        xr, unseen = _reset_unseen(q, x, w, S)
    finally:
        p.sim.close()
    # the drive's variables far off move nothing in 0.3 s: reset; the steering CoR far off is seen
    assert {"drive.Ki", "drive.Kp", "drive.v_ref"} <= set(unseen) and "contact.e_SW" not in unseen, unseen
    x0 = p.x0_vector()
    for i, name in enumerate(p.free):
        assert xr[i] == (x0[i] if name in unseen else x[i]), name


def test_a_shorter_window_starts_from_the_grown_point_at_its_length(start_stop_layout1, monkeypatch, capsys):
    """While the window is in trouble (forced here: the check itself is
    windowing's), the next shorter window of the ladder is refined from the
    trail's point at the longest grown window not beyond it, not from the
    full window's optimum."""
    meas = start_stop_layout1
    truth = true_design_values(load_truth(meas))
    p = drive_known(from_measurement(meas, "LW", window=WINDOW, tare=True, objective="likelihood"), truth)
    monkeypatch.setattr(windowing, "troubles", lambda res: ["forced"] if res.problem.times[-1] > 1.1 else [])
    try:
        res = identify_grown(p, shrink=True, max_evals=30, refine_evals=5, uncertainty=True, seed=1, progress=True)
    finally:
        p.sim.close()
    tried = res.windows
    assert [round(t["window_s"], 1) for t in tried] == [WINDOW, 1.2, 1.0]   # 1.5 and 1.2 forced, 1.0 not
    grown = [g["window_s"] for g in res.grown]
    for t in tried[1:]:
        assert t["from_window_s"] in grown and t["from_window_s"] <= t["window_s"] + 1e-9
    assert res.problem.times[-1] <= 1.0 + 1e-9 and "; windows " in res.message
    assert res.to_dict()["window_s"] == pytest.approx(1.0, abs=0.01)
    bar = capsys.readouterr().err   # the progress bar went through the stages, f shown after each
    assert "4/4" in bar and "edges: f = " in bar


def test_the_windows_can_leave_the_whole_record_to_the_refinement(start_stop_layout1, monkeypatch):
    """grow(whole=False) takes every window of growing.windows but the whole
    record, which identify_grown's refinement (the same Levenberg-Marquardt
    in the same metric) then takes; whole=True ends on the whole record."""
    p = from_measurement(start_stop_layout1, "LW", window=WINDOW, tare=True, objective="likelihood")
    seen = []

    def fake_refine(q, x, **kw):   # the windows' Levenberg-Marquardt, recorded instead of run
        seen.append(round(float(q.times[-1] - q.times[0]), 3))
        return Refined(np.asarray(x, float), 1.0, 1.0, 1, 1)

    monkeypatch.setattr(growing, "refine", fake_refine)
    try:
        duration = float(p.times[-1] - p.times[0]) + float(np.median(np.diff(p.times)))
        steps = growing.windows(duration)
        for whole in (True, False):
            seen.clear()
            _, info = growing.grow(p, start=p.x0_vector(), channel_weights=1.0 / p.noise ** 2, profile_points=0,
                                   whole=whole)
            taken = steps[1:] if whole else steps[1:-1]
            assert len(seen) == 1 + len(taken)   # the first window's refinement from the start point, then each
            assert [round(t["window_s"], 3) for t in info["windows"]] == [round(t, 3) for t in [steps[0], *taken]]
    finally:
        p.sim.close()


def test_grown_refuses_what_it_cannot_do(start_stop_layout1):
    p = from_measurement(start_stop_layout1, "LW", window=0.5, objective="statistics")
    try:
        with pytest.raises(ValueError, match="statistics objective is not a sum of squares"):
            identify_grown(p, max_evals=10)
    finally:
        p.sim.close()
    p = from_measurement(start_stop_layout1, "LW", window=0.5, objective="likelihood")
    try:
        with pytest.raises(ValueError, match="max_evals = 0 must be at least 1"):
            identify_grown(p, max_evals=0)
        with pytest.raises(ValueError, match="needs uncertainty=True"):
            identify_grown(p, max_evals=10, shrink=True)
        with pytest.raises(ValueError, match="start 'first' is not one of complex, single, auto"):
            identify_grown(p, max_evals=10, start="first")
    finally:
        p.sim.close()
