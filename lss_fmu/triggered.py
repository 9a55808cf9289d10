"""Simulations aligned on the trigger point, as the transducer cart logs them.

The photocell starts logging when the transducer cart passes the trigger point
s_M. `simulate_triggered` runs the chain past a settling time, finds the
crossing of s_M (interpolated between communication points, across the wrap
at the track length), and returns the outputs at the requested times after
the crossing, interpolated with cubic splines from a communication grid twice
as fine as the samples.
"""
from __future__ import annotations

from collections import deque
from typing import Mapping, Sequence

import numpy as np
from scipy.interpolate import CubicSpline

from .runner import ChainSimulator, SimulationError
from .variables import FORCE_CHANNELS


def arriving_cart(length: float, n_carts: int, s_m: float, v: float, arrival: float,
                  earliest: float) -> tuple[int, float]:
    """(index, arrival time) of the cart that passes s_m about `arrival` s
    after the start at speed v, and not before `earliest` s; cart i starts at
    i * length / n_carts (the FMU's assembly). Once the chain has settled it
    does not matter which cart carries the transducer, so a simulation picks
    the one that reaches the trigger soon after settling instead of running
    up to a lap first."""
    pitch = length / n_carts
    idx = int(round(((s_m - v * arrival) % length) / pitch)) % n_carts
    t = ((s_m - idx * pitch) % length) / v
    if t < earliest:  # rounding brought it too early: the next cart behind
        idx = (idx - 1) % n_carts
        t = ((s_m - idx * pitch) % length) / v
    return idx, t


def crossing_fraction(s_prev: float, s_cur: float, s_m: float, length: float) -> float | None:
    """Fraction in [0, 1) of the step s_prev -> s_cur at which the cart passes
    s_m moving forward (arc lengths wrap at `length`), or None."""
    moved = (s_cur - s_prev) % length
    if moved <= 0 or moved > 0.5 * length:
        return None
    ahead = (s_m - s_prev) % length
    if ahead < moved or (ahead == 0.0):
        return ahead / moved
    return None


def simulate_triggered(sim: ChainSimulator, params: Mapping[str, object], s_m: float,
                       sample_times: np.ndarray, settle: float = 3.0,
                       channels: Sequence[str] = FORCE_CHANNELS, max_wait: float | None = None,
                       tolerance: float | None = None, step: float | None = None,
                       history: float = 0.0) -> np.ndarray:
    """Outputs `channels` at `sample_times` (s after the trigger crossing) as an
    array (len(sample_times), len(channels)). The communication step is
    `step`, by default half the sample spacing; `history` s before the crossing
    are kept too, so that sample times down to -history can be asked for.
    Raises SimulationError if the run fails or the cart never reaches s_m
    within `max_wait` after settling."""
    dt = float(np.median(np.diff(sample_times))) if len(sample_times) > 1 else 1.0 / 300.0
    h = dt / 2.0 if step is None else float(step)
    past = deque(maxlen=int(np.ceil(history / h)) + 1 if history > 0 else 0)
    duration = float(sample_times[-1]) + 2 * h
    sim.start(params, tolerance=tolerance)
    length = float(sim.get("track.length"))
    v = max(abs(float(params.get("drive.v_ref", 2.0))), 0.1)
    if max_wait is None:
        max_wait = 1.5 * length / v + 1.0
    vr_s = sim.vr("transducer.s")
    vrs = [sim.vr(c) for c in channels]
    fmu = sim.fmu
    t = 0.0
    n_settle = int(np.ceil(settle / h))
    for _ in range(n_settle):
        sim.step(h)
    t = sim.time
    s_prev = fmu.getReal([vr_s])[0]
    t_cross = None
    rows, times = [], []
    limit = t + max_wait
    while t_cross is None:
        if t > limit:
            raise SimulationError(f"the transducer cart did not pass s_M = {s_m:.3f} m within "
                                  f"{max_wait:.1f} s after settling")
        prev_vals = fmu.getReal(vrs)
        sim.step(h)
        t = sim.time
        s_cur = fmu.getReal([vr_s])[0]
        frac = crossing_fraction(s_prev, s_cur, s_m, length)
        if frac is None:
            past.append((t - h, prev_vals))
        else:
            t_cross = t - h + frac * h
            times.extend(tp for tp, _ in past)
            rows.extend(v for _, v in past)
            rows.append(prev_vals)
            times.append(t - h)
            rows.append(fmu.getReal(vrs))
            times.append(t)
        s_prev = s_cur
    while t < t_cross + duration:
        sim.step(h)
        t = sim.time
        rows.append(fmu.getReal(vrs))
        times.append(t)
    data = np.asarray(rows)
    if not np.all(np.isfinite(data)):
        raise SimulationError("the simulated outputs are not finite")
    spline = CubicSpline(np.asarray(times) - t_cross, data, axis=0)
    return spline(sample_times)
