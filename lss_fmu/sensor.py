"""The sensor model of the virtual transducer cart (docs/measurements.md).

The FMU gives the transducer cart's signals as exact point values at its
communication points. A real transducer cart (strain-gauge shear webs in full
bridges, two carrier-frequency amplifiers, inductive wheel-speed pick-ups and a
photocell) records something else; this module turns a finely sampled FMU
record into what the logger writes:

1. Forces: an anti-alias low-pass filter (4th-order Butterworth, 100 Hz,
   causal like the analogue filter of a real amplifier) applied to the record
   at the internal rate (1200 Hz), then sampled at 300 Hz on the trigger's
   time grid (4-point cubic interpolation between internal samples), plus a
   constant offset per channel (drawn once per measurement: the residual
   zero error of the bridges after taring) and white Gaussian noise per
   sample (amplifier and bridge noise), rounded to the logger's 0.01 N.
2. Wheel speeds: each wheel's angle is the integral of its speed; an
   inductive sensor gives 15 pulses per revolution (random phase); the
   counter reports (pulses in the last gate time) x (2 pi / 15) / gate, a
   sliding gate of 0.2 s, so the speed is quantised in steps of
   2 pi / (15 x 0.2 s) = 2.094 rad/s and averaged over the gate.
3. Trigger: logging starts when the transducer cart passes the trigger point
   s_M (the first forward crossing of `transducer.s` through s_M after the
   arming time, the wrap at the track length handled), time 0 is that
   instant, and logging stops when the cart has gone once round (the next
   crossing), or after a given number of samples.

Everything random comes from the numpy Generator the caller passes, so a
measurement is reproducible from its seed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Optional

import numpy as np
import pandas as pd
from scipy import signal

from .variables import FORCE_CHANNELS, SPEED_CHANNELS

CHANNELS = FORCE_CHANNELS + SPEED_CHANNELS
S_CHANNEL = "transducer.s"

# White noise (standard deviation per 300 Hz sample) and the standard deviation
# of the per-measurement constant offset, N. A shear-web transducer in a full
# bridge on a carrier-frequency amplifier resolves about 0.1 % of its range in
# a 100 Hz band; the zero after taring drifts by a few tenths of a percent.
# Ranges: joint x 10 kN, joint y and z 5 kN, wheels 2 kN.
NOISE_STD = {
    "transducer.joint.F_x": 4.0,
    "transducer.joint.F_y": 3.0,
    "transducer.joint.F_z": 3.0,
    "transducer.steering.F_left": 2.0,
    "transducer.steering.F_right": 2.0,
    "transducer.driving.F_left": 2.0,
    "transducer.driving.F_right": 2.0,
}
OFFSET_STD = {
    "transducer.joint.F_x": 15.0,
    "transducer.joint.F_y": 10.0,
    "transducer.joint.F_z": 10.0,
    "transducer.steering.F_left": 6.0,
    "transducer.steering.F_right": 6.0,
    "transducer.driving.F_left": 6.0,
    "transducer.driving.F_right": 6.0,
}
WHEEL_OF = {"transducer.wheel.w_sl": "steering left", "transducer.wheel.w_sr": "steering right",
            "transducer.wheel.w_dl": "driving left", "transducer.wheel.w_dr": "driving right"}


class SensorError(ValueError):
    """The record cannot give a measurement (too short, no trigger, ...)."""


@dataclass(frozen=True)
class SensorModel:
    """The numbers of the sensor model; the defaults are the documented ones."""
    sample_rate: float = 300.0          # Hz, logger
    oversampling: int = 4               # internal rate = oversampling x sample_rate
    filter_order: int = 4               # Butterworth anti-alias filter
    filter_cutoff: float = 100.0        # Hz (-3 dB)
    filter_causal: bool = True          # True: like an analogue filter (group delay ~4 ms); False: zero phase
    noise_std: Mapping[str, float] = field(default_factory=lambda: dict(NOISE_STD))
    offset_std: Mapping[str, float] = field(default_factory=lambda: dict(OFFSET_STD))
    gain: Mapping[str, float] = field(default_factory=dict)   # channel -> gain (1 if absent)
    force_resolution: float = 0.01      # N, the logger's export resolution (0: none)
    pulses_per_rev: int = 15
    gate_time: float = 0.2              # s, sliding counter gate
    speed_resolution: float = 1e-4      # rad/s, export resolution of the speed channels

    @property
    def internal_rate(self) -> float:
        return self.sample_rate * self.oversampling

    @property
    def internal_step(self) -> float:
        return 1.0 / self.internal_rate

    @property
    def speed_quantum(self) -> float:
        """The step of the speed reading, rad/s."""
        return 2.0 * math.pi / (self.pulses_per_rev * self.gate_time)

    def sos(self) -> np.ndarray:
        return signal.butter(self.filter_order, self.filter_cutoff, btype="low", output="sos",
                             fs=self.internal_rate)

    def group_delay(self, f: float = 1.0) -> float:
        """Group delay of the anti-alias filter at frequency f (s); 0 when zero-phase."""
        if not self.filter_causal:
            return 0.0
        b, a = signal.butter(self.filter_order, self.filter_cutoff, fs=self.internal_rate)
        _, gd = signal.group_delay((b, a), w=[f], fs=self.internal_rate)
        return float(gd[0]) / self.internal_rate

    def describe(self) -> dict:
        """The numbers, as written into meta.json."""
        return {
            "sample_rate_Hz": self.sample_rate,
            "internal_rate_Hz": self.internal_rate,
            "anti_alias_filter": f"Butterworth, order {self.filter_order}, {self.filter_cutoff:g} Hz, "
                                 + ("causal" if self.filter_causal else "zero-phase"),
            # a channel without noise is not declared (meta.json refuses sigma = 0: the likelihood
            # weighs by 1 / sigma^2); where it is used its noise is estimated from the residual
            "force_noise_std_N": {c: v for c, v in self.noise_std.items() if v > 0},
            "force_offset_std_N": dict(self.offset_std),
            "force_resolution_N": self.force_resolution,
            "wheel_speed": f"{self.pulses_per_rev} pulses per revolution counted in a sliding "
                           f"{self.gate_time:g} s gate (step {self.speed_quantum:.4f} rad/s)",
            "trigger": "photocell at the trigger point s_M; time 0 = passage; one lap logged",
        }

    def draw_offsets(self, rng: np.random.Generator) -> dict:
        """The constant offset of each force channel for one measurement, N."""
        return {c: float(rng.normal(0.0, self.offset_std.get(c, 0.0))) for c in FORCE_CHANNELS}

    # -- the stages -----------------------------------------------------------------
    def anti_alias(self, x: np.ndarray) -> np.ndarray:
        """Filter a record sampled at the internal rate (axis 0 = time). The causal
        filter starts in the steady state of the first sample (no start transient)."""
        x = np.asarray(x, dtype=float)
        sos = self.sos()
        if not self.filter_causal:
            return signal.sosfiltfilt(sos, x, axis=0)
        zi = signal.sosfilt_zi(sos)  # (n_sections, 2)
        zi = zi[(...,) + (None,) * (x.ndim - 1)] * x[0]
        y, _ = signal.sosfilt(sos, x, axis=0, zi=zi)
        return y

    def acquire(self, record: pd.DataFrame, s_M: float, track_length: float,
                rng: np.random.Generator, arm_time: float = 0.0, offsets: Optional[Mapping] = None,
                n_samples: Optional[int] = None, noise: bool = True, trigger_time: Optional[float] = None):
        """The logger's samples from an FMU record.

        `record`: a DataFrame with 'time' on a uniform grid at `internal_rate`
        (as `ChainSimulator.simulate(step=1/internal_rate)` gives it), the 11
        channels and 'transducer.s'. Returns (samples, info): samples with
        'time' (0 at the trigger) and the 11 channels; info with the trigger and
        stop times in record time, the offsets and the wheel pulse phases.
        `trigger_time`: logging starts then (a start command, not the
        photocell; n_samples must be given)."""
        t = record["time"].to_numpy(dtype=float)
        h = _uniform_step(t, self.internal_step)
        missing = [c for c in CHANNELS + [S_CHANNEL] if c not in record.columns]
        if missing:
            raise SensorError(f"the record lacks {', '.join(missing)}")
        if trigger_time is not None:
            if n_samples is None:
                raise SensorError("a record started by a command (trigger_time) needs n_samples")
            t_on, t_off = float(trigger_time), None
        else:
            t_on, t_off = trigger_times(t, record[S_CHANNEL].to_numpy(dtype=float), s_M, track_length,
                                        arm_time)
        if n_samples is None:
            if t_off is None:
                raise SensorError(f"the record (to t = {t[-1]:.3f} s) ends before the transducer cart "
                                  f"has gone once round from the trigger at t = {t_on:.3f} s")
            n_samples = int(math.ceil((t_off - t_on) * self.sample_rate - 1e-9))
        n_samples = int(n_samples)
        if n_samples < 2:
            raise SensorError(f"n_samples = {n_samples}: at least 2 samples are needed")
        k = np.arange(n_samples)
        tq = t_on + k / self.sample_rate
        if tq[-1] > t[-1] - 2 * h:
            raise SensorError(f"the record (to t = {t[-1]:.3f} s) ends before the last sample at "
                              f"t = {tq[-1]:.3f} s")
        if tq[0] - self.gate_time < t[0]:
            raise SensorError(f"the trigger at t = {t_on:.3f} s comes less than one gate time "
                              f"({self.gate_time} s) after the start of the record")
        out = {"time": k / self.sample_rate}
        # forces
        F = record[FORCE_CHANNELS].to_numpy(dtype=float)
        Ff = self.anti_alias(F)
        Fs = interp_cubic(t[0], h, Ff, tq)
        offsets = dict(offsets) if offsets is not None else self.draw_offsets(rng)
        for j, c in enumerate(FORCE_CHANNELS):
            y = Fs[:, j] * float(self.gain.get(c, 1.0)) + offsets.get(c, 0.0)
            if noise:
                y = y + rng.normal(0.0, self.noise_std.get(c, 0.0), n_samples)
            if self.force_resolution > 0:
                y = np.round(y / self.force_resolution) * self.force_resolution
                y = np.round(y, _decimals(self.force_resolution))
            out[c] = y
        # wheel speeds
        phases = {}
        for c in SPEED_CHANNELS:
            phi0 = float(rng.uniform(0.0, 2.0 * math.pi))
            phases[c] = phi0
            w = pulse_count_speed(t, record[c].to_numpy(dtype=float), tq, self.pulses_per_rev,
                                  self.gate_time, phi0)
            if self.speed_resolution > 0:
                w = np.round(w, _decimals(self.speed_resolution))
            out[c] = w
        samples = pd.DataFrame(out, columns=["time"] + CHANNELS)
        info = {"trigger_time": float(t_on), "stop_time": None if t_off is None else float(t_off),
                "n_samples": n_samples, "offsets_N": offsets, "pulse_phase_rad": phases,
                "full_lap": t_off is not None and n_samples == int(math.ceil((t_off - t_on) * self.sample_rate - 1e-9))}
        return samples, info


def _decimals(resolution: float) -> int:
    return max(0, int(round(-math.log10(resolution))))


def _uniform_step(t: np.ndarray, expected: Optional[float] = None) -> float:
    if len(t) < 4:
        raise SensorError("the record has fewer than 4 samples")
    d = np.diff(t)
    h = (t[-1] - t[0]) / (len(t) - 1)
    if not np.all(np.abs(d - h) <= 1e-6 * h + 1e-12):
        raise SensorError("the record's time grid is not uniform")
    if expected is not None and abs(h - expected) > 1e-6 * expected:
        raise SensorError(f"the record is sampled every {h:.6g} s, the sensor model needs "
                          f"{expected:.6g} s (its internal rate)")
    return h


def trigger_times(t: np.ndarray, s: np.ndarray, s_M: float, track_length: float, arm_time: float = 0.0):
    """When the cart passes s_M going forward for the first time after `arm_time`,
    and when it next passes it (one lap later; None if the record ends first).
    `s` is the arc position, wrapped into [0, track_length); crossing times are
    interpolated linearly between samples."""
    L = float(track_length)
    if not (L > 0):
        raise SensorError(f"track length {L} must be positive")
    if not (0.0 <= s_M < L):
        s_M = s_M % L
    u = np.unwrap(np.asarray(s, dtype=float), period=L)
    lap = np.floor((u - s_M) / L)
    up = np.nonzero((lap[1:] > lap[:-1]) & (t[1:] > arm_time))[0] + 1
    if len(up) == 0:
        raise SensorError(f"the transducer cart never passes the trigger point s_M = {s_M:.3f} m "
                          f"after t = {arm_time:g} s (record to t = {t[-1]:.3f} s)")

    def crossing(i):
        target = s_M + lap[i] * L
        frac = (target - u[i - 1]) / (u[i] - u[i - 1])
        return t[i - 1] + frac * (t[i] - t[i - 1]), target

    i0 = up[0]
    t_on, target = crossing(i0)
    if t_on < arm_time:  # the crossing happened inside the arming step
        if len(up) < 2:
            raise SensorError(f"the transducer cart never passes s_M = {s_M:.3f} m after t = {arm_time:g} s")
        i0 = up[1]
        t_on, target = crossing(i0)
    after = np.nonzero(u[i0:] >= target + L)[0]
    if len(after) == 0:
        return t_on, None
    i1 = i0 + after[0]
    frac = (target + L - u[i1 - 1]) / (u[i1] - u[i1 - 1])
    return t_on, t[i1 - 1] + frac * (t[i1] - t[i1 - 1])


def interp_cubic(t0: float, h: float, y: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """4-point (cubic Lagrange) interpolation of samples y[k] at t0 + k h
    (axis 0), at the times tq (which must lie inside the record)."""
    y = np.asarray(y, dtype=float)
    x = (np.asarray(tq, dtype=float) - t0) / h
    i = np.floor(x).astype(int)
    i = np.clip(i, 1, len(y) - 3)
    f = x - i
    w0 = -f * (f - 1) * (f - 2) / 6.0
    w1 = (f + 1) * (f - 1) * (f - 2) / 2.0
    w2 = -(f + 1) * f * (f - 2) / 2.0
    w3 = (f + 1) * f * (f - 1) / 6.0
    if y.ndim > 1:
        w0, w1, w2, w3 = (w[:, None] for w in (w0, w1, w2, w3))
    return w0 * y[i - 1] + w1 * y[i] + w2 * y[i + 1] + w3 * y[i + 2]


def pulse_count_speed(t: np.ndarray, omega: np.ndarray, tq: np.ndarray, pulses_per_rev: int = 15,
                      gate_time: float = 0.2, phase0: float = 0.0) -> np.ndarray:
    """Wheel speed as a pulse counter reports it: the wheel angle is the integral
    of omega (trapezoidal on the record's grid, linear in between); a pulse is
    given each time the angle (plus phase0) passes a multiple of 2 pi / ppr;
    the reading at tq is (pulses in (tq - gate, tq]) x 2 pi / (ppr gate)."""
    t = np.asarray(t, dtype=float)
    omega = np.asarray(omega, dtype=float)
    phi = np.concatenate([[0.0], np.cumsum(0.5 * (omega[1:] + omega[:-1]) * np.diff(t))])
    pitch = 2.0 * math.pi / pulses_per_rev
    count = lambda tt: np.floor((np.interp(tt, t, phi) + phase0) / pitch)  # noqa: E731
    return (count(tq) - count(np.asarray(tq) - gate_time)) * pitch / gate_time


def trigger_window(record: pd.DataFrame, s_M: float, track_length: float, n_samples: int,
                   sample_rate: float = 300.0, arm_time: float = 0.0,
                   channels=FORCE_CHANNELS, sensor: Optional[SensorModel] = None) -> pd.DataFrame:
    """A simulated record seen through the trigger, without noise or offsets:
    the channels at t_on + k / sample_rate, k < n_samples, time 0 at the trigger
    (cubic interpolation on the record's uniform grid). With `sensor` the
    forces first pass its anti-alias filter (the record must then be sampled at
    its internal rate). For comparing a simulation with a measurement."""
    t = record["time"].to_numpy(dtype=float)
    h = _uniform_step(t, sensor.internal_step if sensor is not None else None)
    t_on, _ = trigger_times(t, record[S_CHANNEL].to_numpy(dtype=float), s_M, track_length, arm_time)
    k = np.arange(int(n_samples))
    tq = t_on + k / sample_rate
    if tq[-1] > t[-1] - 2 * h:
        raise SensorError(f"the record (to t = {t[-1]:.3f} s) ends before the last sample at t = {tq[-1]:.3f} s")
    Y = record[list(channels)].to_numpy(dtype=float)
    if sensor is not None:
        Y = sensor.anti_alias(Y)
    out = pd.DataFrame(interp_cubic(t[0], h, Y, tq), columns=list(channels))
    out.insert(0, "time", k / sample_rate)
    out.attrs["trigger_time"] = float(t_on)
    return out
