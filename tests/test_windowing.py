"""Shorter windows for records that turn chaotic (identification.windowing).

The ladder's logic with a stand-in identification (which windows are tried,
from where, what is returned), and the cut problem against the one
from_measurement builds for the same window. The real layout-5 case is in
tests/test_windowing_layout5.py.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from identification.identify import IdentificationResult
from identification.joint import JointProblem
from identification.problem import from_measurement
from identification.uncertainty import Interval
from identification.windowing import identify_windowed, troubles, truncated
from lss_fmu.design import CORS


def _result(problem, x, f, rough=(), above=False):
    ivs = [Interval(n, float(v), 0.01, float(v) - 0.02, float(v) + 0.02, n not in rough, smooth=n not in rough,
                    at_noise=not above) for n, v in zip(problem.free, x)]
    return IdentificationResult(problem, np.asarray(x), 1.0, np.zeros(7), np.asarray(x), f, np.zeros(7), 1, 1, 0,
                                "stand-in", np.array([f]), 0.5, intervals=ivs)


class StandIn:
    """An identification that is rough in e_SW while the window is longer than `smooth_below`."""

    def __init__(self, smooth_below: float):
        self.smooth_below, self.calls = smooth_below, []

    def __call__(self, problem, **kw):
        w = float(problem.times[-1])
        start = problem.x0_vector()
        self.calls.append((w, dict(zip(problem.free, start)), kw.get("journal")))
        x = start + np.array([0.01 if n in CORS else 0.0 for n in problem.free])   # each run moves on
        rough = ("contact.e_SW",) if w > self.smooth_below + 1e-9 else ()
        return _result(problem, x, 7.0 * w, rough)


@pytest.fixture(scope="module")
def start_stop_layout7(rig_record):
    return rig_record(20, "start-stop", 2.7)


def test_the_cut_problem_is_the_shorter_window(start_stop_layout7):
    p = from_measurement(start_stop_layout7, "LW", window=2.5, tare=True, objective="likelihood")
    q = from_measurement(start_stop_layout7, "LW", window=1.2, tare=True, objective="likelihood")
    c = truncated(p, 1.2)
    np.testing.assert_array_equal(c.samples, q.samples)
    np.testing.assert_array_equal(c.times, q.times)
    assert c.sim is p.sim and c.free == p.free and len(p.times) > len(c.times)
    j = truncated(JointProblem([p, dataclasses.replace(p, name="again")]), 1.0)
    assert isinstance(j, JointProblem) and all(float(part.times[-1]) <= 1.0 for part in j.parts)
    assert "trigger.s_M@1" in j.free
    with pytest.raises(ValueError, match="fewer than two samples"):
        truncated(p, 1e-4)
    with pytest.raises(ValueError, match="positive"):
        truncated(p, -1.0)


def test_the_ladder_stops_at_the_first_smooth_window(start_stop_layout7, tmp_path):
    p = from_measurement(start_stop_layout7, "LW", window=2.5, tare=True, objective="likelihood")
    run = StandIn(smooth_below=1.2)
    res = identify_windowed(p, run, uncertainty=True, journal=tmp_path / "m20.jsonl")
    assert [round(w, 3) for w, _, _ in run.calls] == [2.5, 1.5, 1.2]
    # each run starts where the one before ended
    for (_, before, _), (_, after, _) in zip(run.calls, run.calls[1:]):
        for n in CORS:
            assert after[n] == pytest.approx(before[n] + 0.01)
    # one journal per window, the record's own for the first
    assert [j.name for _, _, j in run.calls] == ["m20.jsonl", "m20.w1.5.jsonl", "m20.w1.2.jsonl"]
    assert [t["troubles"] for t in res.windows] == [["contact.e_SW"], ["contact.e_SW"], []]
    assert res.to_dict()["window_s"] == pytest.approx(1.2, abs=0.01)
    assert res.to_dict()["windows"] == res.windows and "windows 2.5, 1.5, 1.2 s" in res.message


def test_a_smooth_record_keeps_its_window_and_a_chaotic_one_ends_short(start_stop_layout7):
    p = from_measurement(start_stop_layout7, "LW", window=2.5, tare=True, objective="likelihood")
    run = StandIn(smooth_below=9.0)
    res = identify_windowed(p, run, uncertainty=True)
    assert len(run.calls) == 1 and res.windows[0]["troubles"] == [] and res.message == "stand-in"
    run = StandIn(smooth_below=0.5)
    res = identify_windowed(p, run, uncertainty=True)
    assert [round(w, 3) for w, _, _ in run.calls] == [2.5, 1.5, 1.2, 1.0]
    assert troubles(res) == ["contact.e_SW"]   # the shortest window's result, its flags kept
    # a window of the ladder at or above the record's own is skipped
    q = truncated(p, 1.3)
    run = StandIn(smooth_below=0.5)
    identify_windowed(q, run, uncertainty=True)
    assert [round(w, 3) for w, _, _ in run.calls] == [1.3, 1.2, 1.0]


def test_above_the_noise_is_a_trouble_and_intervals_are_needed(start_stop_layout7):
    p = from_measurement(start_stop_layout7, "LW", window=2.5, tare=True, objective="likelihood")
    assert troubles(_result(p, p.x0_vector(), 30.0, above=True)) == ["above the noise"]
    assert troubles(dataclasses.replace(_result(p, p.x0_vector(), 7.0), intervals=None)) == []
    with pytest.raises(ValueError, match="uncertainty=True"):
        identify_windowed(p, StandIn(1.0))


def test_a_campaign_that_shrinks_needs_the_intervals(tmp_path):
    from identification.campaign import run_campaign
    with pytest.raises(ValueError, match="shrink needs uncertainty"):
        run_campaign(tmp_path, ["LW"], tmp_path / "out", shrink=True, uncertainty=False, progress=False)
