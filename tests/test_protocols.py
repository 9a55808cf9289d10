"""Measurement protocols (issue 17): declared in meta.json, checked with a
message naming the field and the value, followed by the virtual transducer
cart and by the identification problem alike."""
from __future__ import annotations

import json

import numpy as np
import pytest

from identification.objective.problem import from_measurement
from lss_fmu import measurement as M
from lss_fmu.protocol import TRANSIENT_TOLERANCE, Protocol, from_meta
from lss_fmu.rig import load_truth, true_design_values
from test_measurement import make_meta, make_samples


# --- the schedules ----------------------------------------------------------------------
def test_schedules():
    up = Protocol("start-up", ramp_time=1.0).schedule(2.0, 2.0)
    assert [up(t) for t in (0.0, 0.5, 1.0, 3.0)] == [0.0, 1.0, 2.0, 2.0]
    step = Protocol("start-up").schedule(2.0, 2.0)
    assert step(0.0) == 2.0                       # ramp 0: a step at the start command
    ss = Protocol("speed-step", step_time=1.0, v_from=1.5, ramp_time=0.0)
    f = ss.schedule(2.2, 2.0)                     # the set point reached 10 % high: v_from too
    assert f(0.5) == pytest.approx(1.65) and f(1.0) == 2.2 and ss.v_before(2.2, 2.0) == pytest.approx(1.65)
    stop = Protocol("stop", step_time=0.5, ramp_time=1.0).schedule(2.0, 2.0)
    assert [stop(t) for t in (0.0, 0.5, 1.0, 1.5, 9.0)] == [2.0, 2.0, 1.0, 0.0, 0.0]
    assert Protocol().schedule(2.5, 2.0)(7.0) == 2.5 and not Protocol().transient
    ss = Protocol("start-stop", step_time=1.0, ramp_time=0.5)
    f = ss.schedule(2.0, 2.0)
    assert [f(t) for t in (0.0, 0.25, 0.5, 0.9, 1.0, 1.25, 1.5, 4.0)] == [0.0, 1.0, 2.0, 2.0, 2.0, 1.0, 0.0, 0.0]
    assert ss.from_rest and ss.transient and ss.v_before(2.0, 2.0) == 0.0
    assert ss.to_meta() == {"name": "start-stop", "step_time": 1.0, "ramp_time": 0.5}
    brake = Protocol("start-stop", step_time=0.8).schedule(1.5, 2.0)
    assert (brake(0.0), brake(0.79), brake(0.8)) == (1.5, 1.5, 0.0)   # ramps 0: full thrust, then full braking


# --- bad input --------------------------------------------------------------------------
BAD = [
    ({"name": "warp"}, "protocol.name", "warp"),
    ({"name": "start-up", "ramp_time": -1}, "protocol.ramp_time", "-1"),
    ({"name": "start-up", "ramp_time": 99.0}, "protocol.ramp_time", "longer than the record"),
    ({"name": "stop"}, "protocol.step_time", "needs"),
    ({"name": "stop", "step_time": 50.0}, "protocol.step_time", "outside the record"),
    ({"name": "speed-step", "step_time": 0.5, "v_from": 30.0}, "protocol.v_from", "30"),
    ({"name": "speed-step", "step_time": 0.5}, "protocol.v_from", "None"),
    ({"name": "steady", "step_time": 1.0}, "protocol.step_time", "no step"),
    ({"name": "start-up", "tempo": 1}, "protocol.tempo", "unknown"),
    ({"name": "start-stop"}, "protocol.step_time", "needs"),
    ({"name": "start-stop", "step_time": -0.5}, "protocol.step_time", "-0.5"),
    ({"name": "start-stop", "step_time": 40.0}, "protocol.step_time", "outside the record"),
    ({"name": "start-stop", "step_time": 0.5, "ramp_time": 99.0}, "protocol.ramp_time", "longer than the record"),
    (["start-up"], "protocol", "object"),
]


@pytest.mark.parametrize("block, field, fragment", BAD, ids=[b[1] + ":" + b[2] for b in BAD])
def test_a_protocol_the_fmu_cannot_follow_is_refused(tmp_path, block, field, fragment):
    meta = make_meta()
    M.write_measurement(tmp_path / "m", make_samples(), meta)
    path = tmp_path / "m" / M.META_FILE
    spoilt = json.loads(path.read_text())
    spoilt["protocol"] = block
    path.write_text(json.dumps(spoilt))
    with pytest.raises(M.MeasurementError) as info:
        M.load_measurement(tmp_path / "m")
    msg = str(info.value)
    assert "meta.json" in msg and field in msg and fragment in msg, msg


def test_a_record_without_a_protocol_is_steady_running():
    assert from_meta({}) == Protocol() and from_meta({"protocol": "stop"}).name == "stop"


# --- followed by the rig and the problem ---------------------------------------------------
@pytest.fixture(scope="module")
def start_up(rig_record):
    return rig_record(20, "start-up", 1.5)


def test_the_rig_writes_what_the_engineer_did(start_up):
    meta = start_up.meta
    assert meta["protocol"] == {"name": "start-up", "ramp_time": 0.0}
    assert start_up.protocol.from_rest and "Start-up from standstill" in meta["notes"]
    F = start_up.forces.to_numpy()
    v = start_up.speeds.to_numpy()
    assert np.all(np.abs(v[0]) < 1e-9)            # the wheels stand still at the start command
    assert F[:, 0].max() - F[:, 0].min() > 200.0  # and the joint force swings as the drive pushes


def test_the_problem_follows_the_record(start_up):
    p = from_measurement(start_up, "LW", tare=True)
    assert p.protocol.from_rest and p.tolerance == TRANSIENT_TOLERANCE
    t = load_truth(start_up)
    vals = true_design_values(t)
    xt = np.array([vals[n] for n in p.free])
    f_truth, f_start = p(xt), p(p.x0_vector())
    # at the truth only the sensor is left (noise, offsets beyond the tare): the
    # start point's CoRs and drive leave several times more
    assert f_truth < 0.2 * f_start, (f_truth, f_start)
    H = p.channel_errors(xt)
    assert H[0] < 0.03, H      # the joint's axial force, the largest span, at the sensor's noise


def test_a_start_stop_is_simulated_as_the_rig_measured_it(rig_record):
    """The rig's start-stop (a start at full thrust, braked 1 s later): the
    chain from rest, the set point back to 0; the problem, reading only the
    record, reproduces it to the sensor's noise at the truth."""
    rec = rig_record(19, "start-stop", 2.0)
    assert rec.meta["protocol"] == {"name": "start-stop", "step_time": 1.0, "ramp_time": 0.0}
    assert "Start-stop from standstill" in rec.meta["notes"]
    v = rec.speeds.to_numpy()
    t = rec.time
    assert np.all(np.abs(v[0]) < 1e-9)
    moving = np.abs(v).max(axis=1)
    assert moving[(t > 0.9) & (t < 1.0)].min() > 0.3 and moving[-1] < moving[(t > 0.9) & (t < 1.0)].min()  # braked
    p = from_measurement(rec, "LW", tare=True)
    assert p.protocol == rec.protocol and p.protocol.from_rest
    vals = true_design_values(load_truth(rec))
    xt = np.array([vals[n] for n in p.free])
    H = p.channel_errors(xt)
    assert H[0] < 0.03, H
    off = xt.copy()
    off[list(p.free).index("contact.e_JA")] += 0.1      # a CoR off by 0.1 shows far above the noise
    from lss_fmu.sensor import NOISE_STD
    from lss_fmu.variables import FORCE_CHANNELS
    sigma = np.array([NOISE_STD[c] for c in FORCE_CHANNELS])
    d_chi2 = np.sum(((p.samples - p.simulate(off)) ** 2 - (p.samples - p.simulate(xt)) ** 2) / sigma ** 2)
    assert d_chi2 > 100.0 and p(off) > p(xt), (d_chi2, p(off), p(xt))
