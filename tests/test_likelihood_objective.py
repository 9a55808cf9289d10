"""The likelihood objective (issue 17): each channel's RMSD over the sensor's
declared noise, so that f is the mean chi^2 per sample, about 7 at the truth,
and a channel counts by what it tells, not by its span."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from identification.objective.jacobian import weights
from identification.objective.problem import drive_known, from_measurement
from identification.pipeline.refine import refine
from lss_fmu import measurement as M
from lss_fmu.design import CORS
from lss_fmu.rig import load_truth, true_design_values
from lss_fmu.sensor import NOISE_STD
from lss_fmu.variables import FORCE_CHANNELS


@pytest.fixture(scope="module")
def record(rig_record):
    return rig_record(5, "start-stop", 1.6)


def _truth(meas, p) -> np.ndarray:
    vals = true_design_values(load_truth(meas))
    return np.array([vals[n] for n in p.free])


def test_at_the_truth_only_the_noise_is_left(record):
    p = from_measurement(record, "LW", tare=True, objective="likelihood")
    np.testing.assert_array_equal(p.noise, [NOISE_STD[c] for c in FORCE_CHANNELS])
    xt = _truth(record, p)
    H = p.channel_errors(xt)
    n = len(p.times)
    # each H_j^2 is chi^2(n) / n: within 5 standard deviations sqrt(2 / n) of 1
    assert np.all(np.abs(H ** 2 - 1.0) < 5.0 * np.sqrt(2.0 / n)), H ** 2
    assert p(xt) == pytest.approx(np.sum(H ** 2))
    # the paper's objective of the same record and point: the same residual, other weights
    q = dataclasses.replace(p, objective="pointwise", noise=None)
    span = np.ptp(p.samples, axis=0)
    np.testing.assert_allclose(q.channel_errors(xt) * span / p.noise, H, rtol=1e-9)


def test_a_wrong_cor_costs_what_the_record_says(record):
    """Moving e_JA by 0.1 raises the likelihood objective by many noise
    quanta (2 / n is one chi^2 unit per channel) while the paper's range-
    normalised f hardly moves: why f / f(truth) = 1.00 told nothing."""
    p = from_measurement(record, "LW", tare=True, objective="likelihood")
    q = dataclasses.replace(p, objective="pointwise", noise=None)
    xt = _truth(record, p)
    off = xt.copy()
    off[list(p.free).index("contact.e_JA")] += 0.1
    n = len(p.times)
    assert (p(off) - p(xt)) * n > 100.0                     # Delta chi^2 > 100
    assert q(off) / q(xt) < 1.2                              # the range-normalised f: well within 20 %


def test_refinement_minimises_the_same_metric(record):
    p = from_measurement(record, "LW", tare=True, objective="likelihood")
    truth = true_design_values(load_truth(record))
    p = drive_known(p, truth)
    np.testing.assert_allclose(weights(p), 1.0 / (len(p.times) * p.noise ** 2))
    x = np.array([truth[n] for n in CORS]) + np.array([0.05, 0.0, -0.05, 0.05])
    r = refine(p, x, max_evals=1, central=False)
    assert r.f_start == pytest.approx(p(x), rel=1e-9)


@pytest.mark.parametrize("spoil, fragment", [
    (lambda s: s.pop("force_noise_std_N"), "is not declared"),
    (lambda s: s["force_noise_std_N"].pop("transducer.joint.F_y"), "transducer.joint.F_y"),
])
def test_a_record_without_its_noise_is_refused_by_name(record, tmp_path, spoil, fragment):
    meta = json.loads((record.path / M.META_FILE).read_text())
    spoil(meta["sensor"])
    M.write_measurement(tmp_path / "m", record.samples, meta)
    meas = M.load_measurement(tmp_path / "m")
    with pytest.raises(ValueError) as info:
        from_measurement(meas, "LW", objective="likelihood")
    msg = str(info.value)
    assert "meta.json" in msg and "force_noise_std_N" in msg and fragment in msg, msg
    from_measurement(meas, "LW")                         # the paper's objective does not need it


@pytest.mark.parametrize("field, channel, value, fragment", [
    ("force_noise_std_N", "transducer.driving.F_left", -2.0, "-2.0"),
    ("force_noise_std_N", "transducer.steering.F_left", "low", '"low"'),
    ("force_noise_std_N", "transducer.joint.F_z", 0.0, "positive"),
    ("force_noise_std_N", "transducer.joint.F_q", 2.0, "unknown force channel"),
    ("force_offset_std_N", "transducer.joint.F_x", -15.0, "-15.0"),
])
def test_a_noise_or_offset_that_cannot_be_is_refused_on_loading(record, tmp_path, field, channel, value, fragment):
    """Refused when the record is read (the close loop would otherwise fall back to an estimate)."""
    meta = json.loads((record.path / M.META_FILE).read_text())
    meta["sensor"][field][channel] = value
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / M.META_FILE).write_text(json.dumps(meta))
    (tmp_path / "m" / "samples.csv").write_text(M.format_samples(record.samples))
    with pytest.raises(M.MeasurementError) as info:
        M.load_measurement(tmp_path / "m")
    msg = str(info.value)
    assert "meta.json" in msg and f"sensor.{field}" in msg and fragment in msg, msg
    if fragment != "unknown force channel":
        assert channel in msg, msg


@pytest.mark.parametrize("rate, fragment", [("fast", "'fast'"), (150.0, "150.0"), (1e9, "1000000000.0")])
def test_a_logger_rate_that_cannot_be_is_refused_by_name(record, tmp_path, rate, fragment):
    """sensor.internal_rate_Hz sets where the simulated forces are filtered:
    one below the sample rate (300 Hz), absurdly high or not a number is
    refused with the file, the field and the value (the cutoff's check:
    tests/test_sensor_in_objective.py)."""
    meta = json.loads((record.path / M.META_FILE).read_text())
    meta["sensor"]["internal_rate_Hz"] = rate
    M.write_measurement(tmp_path / "m", record.samples, meta)
    meas = M.load_measurement(tmp_path / "m")
    with pytest.raises(ValueError) as info:
        from_measurement(meas, "LW")
    msg = str(info.value)
    assert "meta.json" in msg and "sensor.internal_rate_Hz" in msg and fragment in msg, msg


def test_no_interval_is_claimed_from_a_fit_above_the_noise(record):
    """With the noise declared, a fit that stays far above it (here the CoRs
    0.2 off, the drive at the truth) gets no interval: every variable is
    reported not identifiable, saying why; at the truth every interval is
    "at the noise"."""
    from identification.objective.uncertainty import intervals
    p = from_measurement(record, "LW", tare=True, objective="likelihood")
    truth = true_design_values(load_truth(record))
    p = drive_known(p, truth)
    xt = np.array([truth[n] for n in CORS])
    far = np.clip(xt + np.array([0.2, 0.0, -0.2, 0.2]), 0.2, 0.9)
    off = intervals(p, far)
    assert all(iv.at_noise is False and not iv.identifiable for iv in off), off
    assert "above the sensor's noise" in str(off[0])
    assert all(iv.at_noise is True for iv in intervals(p, xt))
    q = dataclasses.replace(p, objective="pointwise", noise=None)
    assert all(iv.at_noise is None for iv in intervals(q, far))   # the paper's objective declares no noise
