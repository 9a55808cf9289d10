"""The logger's anti-alias filter belongs to the model side of the objective.

The virtual transducer cart (and a real amplifier) low-pass filters the forces
before sampling: a causal 4th-order Butterworth at 100 Hz delays them by about
4 ms. A problem made from a measurement whose meta.json declares the filter
passes the simulation through it, so the delay is not counted as model error.
Checked in the release transient of layout 7, where the chain is not yet
chaotic and the simulation at the truth reproduces the record.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from identification.problem import DESIGN, IdentificationProblem, anti_alias_of
from lss_fmu.sensor import CHANNELS, S_CHANNEL, SensorModel
from lss_fmu.variables import FORCE_CHANNELS

CORS = DESIGN[:4]
TRUTH = {"contact.e_JA": 0.46, "contact.e_JR": 0.558, "contact.e_SW": 0.351, "contact.e_RW": 0.645,
         "drive.v_ref": 2.0, "chain.pretension": 0.03, "wheel.mu_roll": 0.015, "trigger.s_M": 0.0,
         "drive.Kp": 500.0, "drive.Ki": 200.0}
FIXED = {"track.guide_gap": -0.0003}
ARM = 0.25   # s: the wheel-speed gate needs 0.2 s of record before the trigger


@pytest.fixture(scope="module")
def logged(sim):
    """The release transient logged by the sensor model without noise or offsets."""
    sensor = SensorModel()
    params = {"layout.name": "layout7", "contact.model": 3, **FIXED,
              **{k: v for k, v in TRUTH.items() if k != "trigger.s_M"}}
    sim.start(params)
    s_m = float(sim.get("transducer.s")) + 0.8          # passed about 0.4 s after the start
    length = float(sim.get("track.length"))
    rec = sim.simulate(1.0, step=sensor.internal_step, params=params, outputs=CHANNELS + [S_CHANNEL])
    samples, _ = sensor.acquire(rec, s_m, length, np.random.default_rng(0), arm_time=ARM,
                                offsets={c: 0.0 for c in FORCE_CHANNELS}, n_samples=150, noise=False)
    return samples, s_m, sensor


def _problem(samples, s_m, anti_alias):
    return IdentificationProblem(samples[FORCE_CHANNELS].to_numpy(float), samples["time"].to_numpy(float),
                                 "layout7", "LW", {k: (0.2, 0.9) for k in CORS}, fixed=FIXED, free=CORS,
                                 x0={**TRUTH, "trigger.s_M": s_m}, settle=ARM, anti_alias=anti_alias)


def test_modelled_filter_removes_the_group_delay_from_the_residual(logged):
    samples, s_m, sensor = logged
    truth = [TRUTH[k] for k in CORS]
    declared = anti_alias_of({"sensor": sensor.describe()})
    assert declared == (4, 100.0, True)
    with_filter = _problem(samples, s_m, declared)
    without = dataclasses.replace(with_filter, anti_alias=None)
    h_with, h_without = with_filter.channel_errors(truth), without.channel_errors(truth)
    # unmodelled, the delay costs 5-15 % per channel (measured: H 0.050-0.149); modelled, what is
    # left (0.005-0.013) is the filter run at 600 Hz instead of the logger's 1200 Hz and the grid
    assert np.sum(h_with ** 2) < 0.05 * np.sum(h_without ** 2), (h_with, h_without)
    assert np.max(h_with) < 0.02, h_with


def test_filter_declarations(caplog):
    assert anti_alias_of({"sensor": {"anti_alias_filter": "Butterworth, order 2, 80 Hz, zero-phase"}}) == \
        (2, 80.0, False)
    assert anti_alias_of({"sensor": {"anti_alias_filter": "an RC filter"}}) is None
    assert anti_alias_of({}) is None
    with pytest.raises(ValueError, match="order 1-10"):
        anti_alias_of({"sensor": {"anti_alias_filter": "Butterworth, order 40, 100 Hz"}})
