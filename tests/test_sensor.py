"""The sensor model on synthetic records (no FMU): noise and offset statistics,
the anti-alias filter, pulse-count wheel speeds and the trigger."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from lss_fmu import sensor as S
from lss_fmu.variables import FORCE_CHANNELS, SPEED_CHANNELS


def synthetic_record(duration, L=100.0, v=2.0, s0=0.0, force=None, omega=40.0, fs=1200.0):
    """A record at the internal rate: constant (or given) forces, a cart moving
    at v from s0 on a loop of length L."""
    t = np.arange(int(round(duration * fs)) + 1) / fs
    data = {"time": t}
    for c in FORCE_CHANNELS:
        data[c] = np.full_like(t, 500.0) if force is None else force(t)
    for c in SPEED_CHANNELS:
        data[c] = np.full_like(t, omega) if np.isscalar(omega) else omega(t)
    data["transducer.s"] = (s0 + v * t) % L
    return pd.DataFrame(data)


def test_noise_and_offset_statistics_long_run():
    """~330 s at 300 Hz (100k samples) of a constant signal: the measured mean is
    the offset that was drawn, the scatter is the documented noise."""
    sensor = S.SensorModel(force_resolution=0.0)
    L, v = 660.0, 2.0
    rec = synthetic_record(336.0, L=L, v=v)
    rng = np.random.default_rng(7)
    samples, info = sensor.acquire(rec, s_M=2.0, track_length=L, rng=rng, arm_time=0.5)
    n = len(samples)
    assert n == math.ceil(L / v * 300) == 99000
    for c in FORCE_CHANNELS:
        err = samples[c].to_numpy() - 500.0
        sd = sensor.noise_std[c]
        assert err.std(ddof=1) == pytest.approx(sd, rel=0.02), c          # 2 % ~ 4.5 sigma of the estimate
        assert err.mean() == pytest.approx(info["offsets_N"][c], abs=5 * sd / math.sqrt(n)), c
    # the offsets themselves: drawn per measurement with the documented spread
    draws = [sensor.draw_offsets(np.random.default_rng([3, k])) for k in range(3000)]
    for c in FORCE_CHANNELS:
        x = np.array([d[c] for d in draws])
        assert x.std(ddof=1) == pytest.approx(sensor.offset_std[c], rel=0.06), c
        assert abs(x.mean()) < 5 * sensor.offset_std[c] / math.sqrt(len(x)), c


def test_documented_levels():
    s = S.SensorModel()
    assert s.sample_rate == 300 and s.internal_rate == 1200
    assert s.noise_std["transducer.joint.F_x"] == 4.0 and s.offset_std["transducer.joint.F_x"] == 15.0
    assert s.pulses_per_rev == 15 and s.gate_time == 0.2
    assert s.speed_quantum == pytest.approx(2 * math.pi / 3)


def test_resolution_and_reproducibility():
    sensor = S.SensorModel()
    rec = synthetic_record(12.0, L=10.0)
    a, ia = sensor.acquire(rec, 3.0, 10.0, np.random.default_rng(1), arm_time=0.5)
    b, ib = sensor.acquire(rec, 3.0, 10.0, np.random.default_rng(1), arm_time=0.5)
    c, _ = sensor.acquire(rec, 3.0, 10.0, np.random.default_rng(2), arm_time=0.5)
    assert a.equals(b) and ia["offsets_N"] == ib["offsets_N"]
    assert not a.equals(c)
    f = a["transducer.joint.F_x"].to_numpy()
    assert np.all(np.abs(f * 100 - np.round(f * 100)) < 1e-6)   # 0.01 N export resolution


def test_anti_alias_filter():
    sensor = S.SensorModel(force_resolution=0.0, noise_std={}, offset_std={})
    fs = sensor.internal_rate
    t = np.arange(int(20 * fs)) / fs
    for f, lo, hi in [(5.0, 0.99, 1.01), (100.0, 0.69, 0.72), (250.0, 0.0, 0.03)]:
        x = np.sin(2 * np.pi * f * t)
        y = sensor.anti_alias(x)[len(t) // 2:]
        gain = y.std() / x[len(t) // 2:].std()
        assert lo <= gain <= hi, (f, gain)
    # the causal filter starts in steady state: a constant passes unchanged
    assert np.allclose(sensor.anti_alias(np.full(100, 7.0)), 7.0)
    # documented group delay at low frequency: about 4 ms
    assert 0.003 < sensor.group_delay(1.0) < 0.0055
    assert S.SensorModel(filter_causal=False).group_delay() == 0.0


def test_wheel_speed_pulse_count():
    sensor = S.SensorModel()
    omega = 41.3
    rec = synthetic_record(30.0, L=50.0, omega=omega)
    samples, _ = sensor.acquire(rec, 5.0, 50.0, np.random.default_rng(0), arm_time=1.0)
    q = sensor.speed_quantum
    for c in SPEED_CHANNELS:
        w = samples[c].to_numpy()
        k = w / q
        assert np.allclose(k, np.round(k), atol=1e-4), c                # whole pulses in the gate
        assert set(np.round(k).astype(int)) <= {math.floor(omega / q), math.ceil(omega / q)}
        assert w.mean() == pytest.approx(omega, abs=0.02 * omega)     # unbiased on average


def test_wheel_speed_follows_a_ramp():
    t = np.linspace(0, 20, 20001)
    omega = 30 + 0.5 * t
    tq = np.arange(2.0, 19.0, 0.5)
    w = S.pulse_count_speed(t, omega, tq, 15, 0.2, 0.3)
    assert np.all(np.abs(w - (30 + 0.5 * (tq - 0.1))) <= 2 * math.pi / 3 + 1e-9)


def test_trigger_wrap_and_one_lap():
    L, v = 40.0, 2.5
    for s_M, s0 in [(39.9, 30.0), (0.05, 30.0), (12.0, 35.0)]:
        rec = synthetic_record(40.0, L=L, v=v, s0=s0)
        t_on, t_off = S.trigger_times(rec["time"].to_numpy(), rec["transducer.s"].to_numpy(), s_M, L, 1.0)
        expect = ((s_M - s0) % L) / v
        if expect <= 1.0:
            expect += L / v
        assert t_on == pytest.approx(expect, abs=1e-9)
        assert t_off - t_on == pytest.approx(L / v, abs=1e-9)
        samples, info = S.SensorModel().acquire(rec, s_M, L, np.random.default_rng(0), arm_time=1.0)
        assert len(samples) == math.ceil(L / v * 300) and info["full_lap"]
        assert samples["time"].iloc[0] == 0.0


def test_trigger_errors():
    rec = synthetic_record(5.0, L=100.0, v=2.0, s0=0.0)
    with pytest.raises(S.SensorError, match="never passes the trigger point"):
        S.SensorModel().acquire(rec, 50.0, 100.0, np.random.default_rng(0), arm_time=0.5)
    rec = synthetic_record(30.0, L=100.0, v=2.0, s0=0.0)
    with pytest.raises(S.SensorError, match="ends before the transducer cart has gone once round"):
        S.SensorModel().acquire(rec, 10.0, 100.0, np.random.default_rng(0), arm_time=0.5)
    samples, info = S.SensorModel().acquire(rec, 10.0, 100.0, np.random.default_rng(0), arm_time=0.5,
                                            n_samples=600)
    assert len(samples) == 600 and not info["full_lap"]
    with pytest.raises(S.SensorError, match="internal rate"):
        S.SensorModel().acquire(rec.iloc[::2], 10.0, 100.0, np.random.default_rng(0), n_samples=10)


def test_cubic_interpolation_exact_for_cubics():
    h, t0 = 0.01, 0.3
    t = t0 + h * np.arange(200)
    y = 2 - t + 3 * t ** 2 - 0.5 * t ** 3
    tq = np.linspace(0.32, 2.2, 77)
    assert np.allclose(S.interp_cubic(t0, h, y, tq), 2 - tq + 3 * tq ** 2 - 0.5 * tq ** 3, atol=1e-12)


def test_trigger_window_lines_up_shifted_records():
    """The same spatial signal recorded from two start positions lines up at the trigger."""
    L, v = 30.0, 2.0
    shape = lambda s: 400 + 100 * np.sin(2 * np.pi * s / 7.5) + 30 * np.cos(2 * np.pi * s / 1.25)  # noqa: E731
    wins = []
    for s0 in (3.0, 17.3):
        rec = synthetic_record(25.0, L=L, v=v, s0=s0)
        for c in FORCE_CHANNELS:
            rec[c] = shape(rec["transducer.s"].to_numpy())
        wins.append(S.trigger_window(rec, 11.0, L, 1500, arm_time=0.5))
    assert np.allclose(wins[0][FORCE_CHANNELS].to_numpy(), wins[1][FORCE_CHANNELS].to_numpy(), atol=0.05)
