"""Shorter windows for records that turn chaotic (identification.pipeline.windowing).

The cut problem against the one from_measurement builds for the same window,
and what counts as a trouble. The shrink stage itself runs in
tests/test_grown_identification.py.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from identification.pipeline.identify import IdentificationResult
from identification.objective.joint import JointProblem
from identification.objective.problem import from_measurement
from identification.objective.uncertainty import Interval
from identification.pipeline.windowing import troubles, truncated


def _result(problem, x, f, rough=(), above=False, later=None):
    ivs = [Interval(n, float(v), 0.01, float(v) - 0.02, float(v) + 0.02, n not in rough, smooth=n not in rough,
                    at_noise=not above, claimable_shorter=None if later is None else n in later)
           for n, v in zip(problem.free, x)]
    return IdentificationResult(problem, np.asarray(x), 1.0, np.zeros(7), np.asarray(x), f, np.zeros(7), 1, 1, 0,
                                "stand-in", np.array([f]), 0.5, intervals=ivs)


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


def test_above_the_noise_is_a_trouble_and_intervals_are_needed(start_stop_layout7):
    p = from_measurement(start_stop_layout7, "LW", window=2.5, tare=True, objective="likelihood")
    assert troubles(_result(p, p.x0_vector(), 30.0, above=True)) == ["above the noise"]
    assert troubles(_result(p, p.x0_vector(), 7.0, rough=("contact.e_SW",))) == ["contact.e_SW"]
    assert troubles(_result(p, p.x0_vector(), 7.0)) == []
    assert troubles(dataclasses.replace(_result(p, p.x0_vector(), 7.0), intervals=None)) == []


def test_a_rough_cor_the_shorter_window_cannot_claim_is_no_trouble(start_stop_layout7):
    """Shortening for a CoR the shorter window would not claim either gains
    nothing on it: only the rough CoRs that window could claim are troubles."""
    p = from_measurement(start_stop_layout7, "LW", window=2.5, tare=True, objective="likelihood")
    x = p.x0_vector()
    rough = ("contact.e_JR", "contact.e_SW")
    assert troubles(_result(p, x, 7.0, rough=rough, later=("contact.e_SW",))) == ["contact.e_SW"]
    assert troubles(_result(p, x, 7.0, rough=rough, later=())) == []
    assert troubles(_result(p, x, 30.0, rough=rough, later=(), above=True)) == ["above the noise"]
