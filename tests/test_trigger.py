"""The photocell trigger of the identification's simulations (issue 18, item 6).

The first sample of a simulated record must not depend on how long the
record is, nor on how its time column was rounded; and a crossing of the
trigger point just after the trigger is armed must be that crossing, not
one a lap later, for the model (lss_fmu.triggered) as for the rig
(lss_fmu.sensor.trigger_times).
"""
from __future__ import annotations

import numpy as np
import pytest

from lss_fmu.sensor import trigger_times
from lss_fmu.triggered import simulate_triggered
from lss_fmu.variables import FORCE_CHANNELS

PARAMS = {"layout.name": "layout7", "drive.v_ref": 2.0, "chain.transducer": 0}
S_M = 0.9          # m: cart 0 starts just behind it and passes it about 0.4 s after the start
RATE = 300.0


def _run(sim, n, settle=0.05, times=None, **kw):
    t = np.arange(n) / RATE if times is None else times
    info = {}
    y = simulate_triggered(sim, PARAMS, S_M, t, settle=settle, info=info, **kw)
    return y, info


@pytest.mark.parametrize("settle", [0.05, 0.2])
def test_first_samples_do_not_depend_on_the_record_length(sim, settle):
    ref, info0 = _run(sim, 23, settle)
    for n in (24, 97, 150, 301):
        y, info = _run(sim, n, settle)
        assert info["t_cross"] == info0["t_cross"]
        np.testing.assert_array_equal(y[:23], ref)


def test_first_samples_do_not_depend_on_the_rounding_of_the_time_column(sim):
    n = 120
    ref, info0 = _run(sim, n)
    for t in (np.linspace(0.0, (n - 1) / RATE, n), np.arange(0.0, n / RATE - 1e-9, 1.0 / RATE),
              np.round(np.arange(n) / RATE, 6), np.cumsum(np.r_[0.0, np.full(n - 1, 1.0 / RATE)])):
        y, info = _run(sim, n, times=t)
        assert info["t_cross"] == info0["t_cross"]   # the same crossing on the same grid
        np.testing.assert_array_equal(y[0], ref[0])   # t = 0 in every column
        # elsewhere the columns differ by their rounding (up to 5e-7 s): the samples by no more
        # than the forces move in that time
        dt = np.abs(t - np.arange(n) / RATE).max()
        slope = np.abs(np.diff(ref, axis=0)).max(axis=0) * RATE
        assert np.all(np.abs(y - ref) <= 2 * slope * dt + 1e-9)


def test_through_the_problem_records_of_several_lengths_agree(fmu_file):
    from identification.loop.synthetic import release_problem
    x = [0.46, 0.558, 0.351, 0.645]
    short = release_problem(window=0.2).simulate(x)
    for window in (0.35, 0.6, 1.0):
        y = release_problem(window=window).simulate(x)
        np.testing.assert_array_equal(y[:len(short)], short)


@pytest.mark.parametrize("delta", [1e-9, 1e-6, 1e-4, 0.3 / 600, 0.999 / 600, 1.5 / 600, 0.02])
def test_a_crossing_just_after_arming_is_that_crossing(sim, delta):
    """Armed delta s before the crossing (within the step, at its start, a step
    before): the record starts at that crossing, exactly as when armed long before."""
    ref, info0 = _run(sim, 60, settle=0.05)
    tc = info0["t_cross"]
    y, info = _run(sim, 60, settle=tc - delta, max_wait=2.0)
    assert abs(info["t_cross"] - tc) < 1e-12
    np.testing.assert_array_equal(y, ref)


def test_armed_just_after_the_crossing_waits_for_the_next_one(sim):
    """Armed a hair after the crossing: not that one (the cart does not come
    back within max_wait), as the rig's rule says."""
    _, info0 = _run(sim, 10, settle=0.05)
    from lss_fmu.runner import SimulationError
    with pytest.raises(SimulationError, match="did not pass"):
        _run(sim, 10, settle=info0["t_cross"] + 1e-6, max_wait=2.0)


@pytest.mark.parametrize("delta", [1e-6, 2e-4, 0.9 / 1200])
def test_model_and_rig_take_the_same_crossing_near_arming(sim, delta):
    """The rig's rule on its 1200 Hz record and the model's on its 600 Hz grid
    pick the same crossing when the trigger is armed just before it."""
    h = 1.0 / 1200.0
    rec = sim.simulate(1.0, step=h, params=PARAMS, outputs=["transducer.s"] + FORCE_CHANNELS)
    L = float(sim.get("track.length"))
    t_rig, _ = trigger_times(rec["time"].to_numpy(), rec["transducer.s"].to_numpy(), S_M, L, arm_time=0.05)
    for arm in (t_rig - delta, t_rig - 5 * delta):
        t_on, _ = trigger_times(rec["time"].to_numpy(), rec["transducer.s"].to_numpy(), S_M, L, arm_time=arm)
        assert abs(t_on - t_rig) < 1e-9
        _, info = _run(sim, 30, settle=arm, max_wait=2.0)
        assert abs(info["t_cross"] - t_rig) < 2e-6   # linear interpolation on two grids of a smooth s(t)
