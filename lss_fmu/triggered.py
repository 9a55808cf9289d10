"""Simulations aligned on the trigger point, as the transducer cart logs them.

The photocell starts logging when the transducer cart passes the trigger point
s_M. `simulate_triggered` arms the trigger at a given time, finds the first
forward crossing of s_M at or after it (interpolated within the step, across
the wrap at the track length: the rule of the virtual transducer cart,
lss_fmu.sensor.trigger_times), and returns the outputs at the requested
times after the crossing, interpolated with 4-point cubics from a
communication grid twice as fine as the samples.

The grid is k * h exactly, h from the sample rate, so the first samples do
not depend on how long the record is or on the rounding of its time column.
"""
from __future__ import annotations

from collections import deque
from typing import Callable, Mapping, Optional, Sequence

import numpy as np

from .runner import ChainSimulator, SimulationError
from .sensor import interp_cubic
from .variables import FORCE_CHANNELS

S_CHANNEL = "transducer.s"


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
    """Fraction in [0, 1] of the step s_prev -> s_cur at which the cart passes
    s_m moving forward (arc lengths wrap at `length`), or None."""
    moved = (s_cur - s_prev) % length
    if moved <= 0 or moved > 0.5 * length:
        return None
    ahead = (s_m - s_prev) % length
    if ahead <= moved:
        return ahead / moved
    return None


def sample_rate_of(times: np.ndarray) -> float:
    """The sample rate of a regular time column (Hz): from the whole span (the
    median spacing of a column rounded to 1 us is off by 1e-4), snapped to a
    whole number of Hz when within 1e-4 of it, else rounded to 1e-3 Hz, so
    that neither the last bits of the spacing nor the column's rounding change
    the simulation grid (issue 18)."""
    times = np.asarray(times, float)
    if len(times) < 2 or not times[-1] > times[0]:
        return 300.0
    rate = (len(times) - 1) / float(times[-1] - times[0])
    whole = round(rate)
    if whole > 0 and abs(rate - whole) <= 1e-4 * rate:
        return float(whole)
    return round(rate, 3)


def simulate_triggered(sim: ChainSimulator, params: Mapping[str, object], s_m: float,
                       sample_times: np.ndarray, settle: float = 3.0,
                       channels: Sequence[str] = FORCE_CHANNELS, max_wait: float | None = None,
                       tolerance: float | None = None, step: float | None = None,
                       history: float = 0.0, sample_rate: Optional[float] = None,
                       after_trigger: Optional[Callable[[float], float]] = None,
                       info: Optional[dict] = None) -> np.ndarray:
    """Outputs `channels` at `sample_times` (s after the trigger crossing) as an
    array (len(sample_times), len(channels)).

    The trigger is armed at t = `settle` s after the start; the first forward
    crossing of s_m at or after that instant is time 0. The communication step
    is `step`, by default half the sample spacing 1 / `sample_rate` (by
    default read off sample_times, see sample_rate_of); `history` s before the
    crossing are kept too, so that sample times down to -history can be asked
    for. `after_trigger`: the speed set point as a function of the time since
    the trigger (a speed step, a stop); params' drive.v_ref holds until then.
    `info` (a dict) gets the crossing time t_cross, the arming time t_arm and
    the grid step h, in simulation time.
    Raises SimulationError if the run fails or the cart never reaches s_m
    within `max_wait` s after arming."""
    sample_times = np.asarray(sample_times, float)
    rate = float(sample_rate) if sample_rate is not None else sample_rate_of(sample_times)
    h = 0.5 / rate if step is None else float(step)
    duration = float(sample_times[-1]) + 2 * h
    v_before = float(params.get("drive.v_ref", 2.0))
    t_cross = None
    inputs = None if after_trigger is None else {
        "drive.v_ref": lambda t: v_before if t_cross is None else after_trigger(t - t_cross)}
    stream = sim.stream(h, [S_CHANNEL, *channels], params, tolerance, inputs=inputs)
    length = float(sim.get("track.length"))
    v = max(abs(v_before), 0.1)
    if max_wait is None:
        max_wait = 1.5 * length / v + 1.0
    t_arm = float(settle)
    keep = int(np.ceil(history / h)) + 2      # rows before the crossing: history and the cubic's support
    past: deque = deque(maxlen=keep)
    t_prev = s_prev = t0 = None
    rows: list = []
    for t, val in stream:
        s = float(val[0])
        if t_cross is None:
            if t_prev is not None and t > t_arm:
                frac = crossing_fraction(s_prev, s, s_m, length)
                if frac is not None:
                    tc = t_prev + frac * (t - t_prev)
                    if tc >= t_arm:
                        t_cross = tc
                        rows = [r for _, r in past]
                        t0 = past[0][0] if past else t
            if t_cross is None:
                if t > t_arm + max_wait:
                    raise SimulationError(f"the transducer cart did not pass s_M = {s_m:.3f} m within "
                                          f"{max_wait:.1f} s after the trigger was armed at t = {t_arm:g} s")
                past.append((t, val[1:].copy()))
                t_prev, s_prev = t, s
                continue
        rows.append(val[1:].copy())
        if t >= t_cross + duration:
            break
    data = np.asarray(rows)
    if not np.all(np.isfinite(data)):
        raise SimulationError("the simulated outputs are not finite")
    if info is not None:
        info.update({"t_cross": float(t_cross), "t_arm": t_arm, "h": h})
    return interp_cubic(t0 - t_cross, h, data, sample_times)


def simulate_from_rest(sim: ChainSimulator, params: Mapping[str, object], sample_times: np.ndarray,
                       channels: Sequence[str] = FORCE_CHANNELS, tolerance: float | None = None,
                       sample_rate: Optional[float] = None, history: float = 0.0,
                       speed: Optional[Callable[[float], float]] = None) -> np.ndarray:
    """Outputs `channels` at `sample_times` (s after the start command) of a
    chain that starts at rest at t = 0 (params start it at rest: chain.v_init
    0 and usually chain.relax_time > 0); `speed` is the set point as a
    function of time. Before the start the chain stands still, so sample
    times down to -history take the values at t = 0. The grid is k * h, h
    half the sample spacing, as in simulate_triggered."""
    sample_times = np.asarray(sample_times, float)
    rate = float(sample_rate) if sample_rate is not None else sample_rate_of(sample_times)
    h = 0.5 / rate
    t_end = float(sample_times[-1]) + 2 * h
    inputs = None if speed is None else {"drive.v_ref": speed}
    rows = []
    for t, val in sim.stream(h, list(channels), params, tolerance, inputs=inputs):
        rows.append(val.copy())
        if t >= t_end:
            break
    lead = int(np.ceil(history / h)) + 2          # the standstill before the start, for the cubic's support
    data = np.concatenate([np.repeat(rows[:1], lead, axis=0), np.asarray(rows)])
    if not np.all(np.isfinite(data)):
        raise SimulationError("the simulated outputs are not finite")
    return interp_cubic(-lead * h, h, data, sample_times)
