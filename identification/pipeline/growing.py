"""A base identification that grows its window (issue 18).

On the release transient the chain's response is a smooth function of the
CoRs for the first few tenths of a second and grows rough with time: over a
whole second of it the complex stops in another valley on many records (the
close loop's clean records with the transducer on carts 7, 13, 20, 33 and 46:
6 of 16 stayed 56 to 204 times above the noise), and a base above the noise
hands its remainder to whatever flexible candidate is tested next.

So the base is found where the objective is smooth and then carried along:
the complex (and the profile of the least-determined variable, e_JR's
valleys being narrow) on the record's first `first` seconds, then
Levenberg-Marquardt in the likelihood's metric on windows growing by
GROWTH each step up to the whole record, each from the point before. A
continuation in the window length: the optimum moves little from one window
to the next, and the local method follows it where a global one on the
whole window would not find it. On the 16 clean synthetic records all 16
reached the noise (S within 1.11 of its value at the truth, 12 CPU-s each).
Nothing of the truth is used.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import time
from pathlib import Path
from typing import Callable, Mapping, Optional, Sequence

import numpy as np

from lss_fmu.design import TRIGGER
from lss_fmu.runner import TUNABLE
from lss_fmu.variables import FORCE_CHANNELS

from .base_polish import STEP, profile_polish
from .identify import identify
from ..objective.noise import noise_levels
from ..objective.problem import IdentificationProblem, tared
from .refine import refine
from .rest_fit import fit_rest, without
from ..objective.uncertainty import at_noise
from .windowing import truncated

log = logging.getLogger(__name__)

FIRST = 0.3        # s, the first window: smooth on every clean release transient tried
GROWTH = 1.45      # each window this much longer than the one before (0.3, 0.44, 0.63, 0.91, ... s)
STEP_ITERATIONS = 3  # a window's budget: this many Levenberg-Marquardt iterations with central Jacobians
UNSEEN_STEP = 0.05   # share of a variable's range moved to see whether the first window sees it ...
UNSEEN_DS = 1e-6     # ... S changing by less than this (a chi^2 unit is 1): not seen at all
CARRY_STEPS = False  # each window's Jacobian steps scaled from the window before's (fewer simulations) ...
BROYDEN = False      # ... and the window's Jacobian updated after each step, not differenced again (refine's
                     # broyden): 0.76-0.82 of the CPU on five recovery measurements, but not yet the default:
                     # docs/benchmarks.md, "Levers measured, not taken"
RETRY_Z = 3.0        # a retry is asked where the first window's S is this many sd of chi^2 above its mean
                     # (no margin): stricter than the at-noise test of the intervals, as the retry only
                     # costs simulations and is taken only where it fits the first window better (on one
                     # layout-4 record the complex ended at 1.15 per sample, 4.6 sd, its trail off the
                     # truth's valley)


def windows(duration: float, first: float = FIRST, growth: float = GROWTH) -> list:
    """The windows, s: `first` growing by `growth` up to `duration`, the last
    one the whole record (a last step shorter than a tenth of a growth step
    is merged into it)."""
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"record duration {duration!r} s: must be a positive number of seconds")
    if not (math.isfinite(first) and first > 0):
        raise ValueError(f"first window {first!r} s: must be a positive number of seconds")
    if not (math.isfinite(growth) and growth > 1.0):
        raise ValueError(f"window growth {growth!r}: must be a number above 1")
    out, t = [], float(first)
    while t < duration * (1.0 - 1e-9):
        out.append(t)
        t *= growth
    if out and duration / out[-1] < 1.0 + 0.1 * (growth - 1.0):
        out.pop()
    return out + [float(duration)]


def at_rest(problem) -> list:
    """The free variables that set a chain at rest (a start from rest relaxes
    again for each value): the trigger points, where the chain stands, and
    every FMU value the relaxation reads (not tunable: the pretension); none
    for a record that does not start from rest."""
    if not getattr(problem.protocol, "from_rest", False):
        return []
    return [n for n in problem.free if n.partition("@")[0] == TRIGGER
            or (n.partition("@")[0] not in TUNABLE and "." in n)]


def grow(problem: IdentificationProblem, *, evals: int = 400, noise_std: Optional[Mapping[str, float]] = None,
         first: float = FIRST, growth: float = GROWTH, profile_points: int = 9, seed: int = 0,
         journal: Optional[Path] = None, hold: Sequence[str] = (),
         channel_weights: Optional[np.ndarray] = None, keep_points: bool = False,
         reset_unseen: bool = False, start: Optional[Sequence[float]] = None,
         retry: Optional[Callable[[], tuple]] = None, workers: int = 1, hold_rest: bool = False,
         whole: bool = True) -> tuple:
    """(x, info): the problem's optimum found on its first window (the complex
    with `evals` evaluations, then the profile of its least-determined
    variable over `profile_points` values) and followed by
    Levenberg-Marquardt over growing windows to the whole record, in the
    likelihood's metric (1 / sigma^2 per channel: `noise_std` declared, N by
    channel name, else estimated from the first window's residual). `info`
    lists each window's S per sample (about 1 at the noise) and the
    simulations spent. `hold`: variables kept at their start values
    (problem.x0) on the first window, freed from the second on (an effect
    the first window may not see: a bump passed later). `channel_weights`:
    the metric given (1 / sigma^2 per column) instead of noise_std's.
    `keep_points`: each window's entry also holds its point (`x`), from
    which a shorter window can be taken up (identification.pipeline.identify_grown).
    `reset_unseen`: a variable the first window cannot see (S moves by less
    than UNSEEN_DS when it moves by UNSEEN_STEP of its range either way) goes
    back to its start value before the windows grow: the complex left it
    wherever its last point happened to put it (a start-stop's first 0.3 s,
    the drive saturated: v_ref, K_P and K_I move nothing, and K_P was left
    1240 above the truth, which the stop at 1 s could not undo). `info`
    lists them (`unseen`). `start`: a point to take the first window up from
    instead of the complex (Levenberg-Marquardt there; nothing is reset: the
    point is not the complex's random leftover, nor is it profiled again):
    identification.pipeline.joint_start. `retry`: called (no arguments; returns a
    point and the simulations it spent) when the complex's first window
    stays above the declared noise (uncertainty.at_noise, RETRY_Z sd; the
    likelihood objective only); Levenberg-Marquardt on the first window from that
    point, and the better of the two goes on (`info["retry"]`). Where the
    complex's first window is at the noise nothing changes. Every window's
    entry lists the records whose S at its end lies RETRY_Z sd above the
    noise (`records_off`). `workers`: the complex's candidates side by side
    (identify; the serial run's result). `hold_rest`: the complex (and the
    profile) hold what sets the chain at rest (at_rest: the pretension, the
    trigger points) where rest_fit.fit_rest puts them on the first window,
    so each record relaxes once instead of once per evaluation;
    Levenberg-Marquardt then frees them on the first window
    (`info["rest_held"]`, the values held in `info["rest_fit"]`).
    `whole`: False stops at the last window shorter than the record, for a
    caller whose own Levenberg-Marquardt on the whole record, in the same
    metric, follows (identify_grown's refinement): that window would be a
    first, coarser pass of the same minimisation.
    """
    t0 = time.process_time()
    duration = float(problem.times[-1] - problem.times[0]) + float(np.median(np.diff(problem.times)))
    steps = windows(duration, first, growth)
    q = truncated(problem, problem.times[0] + steps[0]) if len(steps) > 1 else problem
    hold = [n for n in hold if n in problem.free]
    rest = [n for n in at_rest(problem) if n not in hold] if hold_rest and start is None else []
    q0 = dataclasses.replace(q, free=tuple(n for n in problem.free if n not in hold),
                             fixed={**q.fixed, **{n: problem.x0[n] for n in hold}}) if hold else q
    per_window = STEP_ITERATIONS * (2 * len(problem.free) + 2) + 1
    held, nfev = {}, 0
    if rest:
        held, nfev = fit_rest(q0, rest, channel_weights, per_window)
    q1 = without(q0, rest, held) if rest else q0
    if start is None:
        res = identify(q1, max_evals=max(int(evals), len(q1.free) + 3), seed=seed, progress=False, journal=journal,
                       workers=workers)
        x1 = np.asarray(res.x, float)
        nfev += int(getattr(res, "nfev", evals))
    else:
        lo, hi = np.array(q1.bounds_array, float).T
        x1 = np.clip(np.asarray(start, float), lo, hi)
    if channel_weights is not None:
        w = np.asarray(channel_weights, float)
        S = float(np.sum(tared(q1.samples - q1.simulate(x1), q1.tare) ** 2 * w))
    else:
        w, S = _weights(q1, x1, noise_std)
    if profile_points > 1 and start is None:
        try:
            xp, S, pinfo = profile_polish(q1, x1, w, points=profile_points)
            x1, nfev = np.asarray(xp, float), nfev + int(pinfo.get("nfev", 0))
        except Exception as exc:   # the complex's point stands
            log.warning("grow: profile on the first window failed: %s", exc)
    if rest:   # the rest's variables freed on the first window, from the values the complex held
        vals = {**held, **dict(zip(q1.free, map(float, x1)))}
        q1, x1 = q0, np.array([vals[n] for n in q0.free])
        r1 = refine(q1, x1, max_evals=per_window, central=True, channel_weights=w, rel_step=STEP)
        nfev += r1.nfev   # S stands: the same simulation
        if np.isfinite(r1.f) and r1.f < S:
            x1, S = np.asarray(r1.x, float), float(r1.f)
    if start is not None:
        r1 = refine(q1, x1, max_evals=per_window, central=True, channel_weights=w, rel_step=STEP)
        nfev += r1.nfev
        if np.isfinite(r1.f) and r1.f < S:
            x1, S = np.asarray(r1.x, float), float(r1.f)
    unseen, retried = [], None
    if reset_unseen and start is None:
        x1, unseen = _reset_unseen(q1, x1, w, S)
        nfev += 2 * len(q1.free)
    if retry is not None and start is None and not hold \
            and at_noise(q1, S / np.shape(q1.samples)[0], z=RETRY_Z, margin=0.0) is False:
        x1, S, unseen, retried, used = _retried(q1, x1, S, unseen, retry, w, per_window)
        nfev += used
    vals = {**{n: problem.x0[n] for n in hold}, **dict(zip(q1.free, map(float, x1)))}
    x = np.array([vals[n] for n in problem.free])
    trail = [{"window_s": steps[0], "S_per_sample": float(S) / q.samples.size}]
    if keep_points:
        trail[0]["x"] = x.tolist()
    carried = None
    for t in (steps[1:] if whole else steps[1:-1]):
        q = truncated(problem, problem.times[0] + t) if t < duration else problem
        r = refine(q, x, max_evals=per_window, central=True, channel_weights=w, rel_step=STEP,
                   steps=carried if CARRY_STEPS else None, broyden=BROYDEN)
        carried = getattr(r, "steps", None) if getattr(r, "steps", None) is not None else carried
        nfev += r.nfev
        # refine's f is S in the same metric at its point: no simulation more
        xr, fr = (np.asarray(r.x, float), float(r.f)) if np.isfinite(r.f) else (x, float("inf"))
        off = records_off(q, r.sim, w) if getattr(r, "sim", None) is not None and np.isfinite(r.f) else []
        x = xr
        trail.append({"window_s": t, "S_per_sample": fr / q.samples.size})
        if off:
            trail[-1]["records_off"] = [int(k) for k in off]
        if keep_points:
            trail[-1]["x"] = x.tolist()
    return x, {"windows": trail, "nfev": nfev, "cpu_s": time.process_time() - t0, "unseen": unseen,
               "retry": retried, "rest_held": rest, "rest_fit": held}


def records_off(q, sim, w, z: float = RETRY_Z) -> list:
    """The records (column blocks of 7: a joint problem's records side by
    side) whose S at `sim` lies more than `z` sd of chi^2 above its mean,
    with no margin. Per record, as the joint S hides one record carried off
    by the others' fit (a layout-6 fit at 1.2 s: 1.126 per sample on its first
    record, 1.035 and 1.048 on the others, 1.07 together, at the noise by
    the joint test of uncertainty.at_noise)."""
    per, limit = record_S(q, sim, w, z)
    return [j for j, S in enumerate(per) if S > limit]


def record_S(q, sim, w, z: float = RETRY_Z) -> tuple:
    """(S per sample of each record at `sim`, the limit records_off puts on
    it: 1 + z sd of chi^2)."""
    r = tared(q.samples - sim, q.tare) ** 2 * np.asarray(w, float)
    n, m = r.shape
    k = len(FORCE_CHANNELS) if m % len(FORCE_CHANNELS) == 0 else m
    per = [float(np.mean(r[:, j * k:(j + 1) * k])) for j in range(m // k)]
    return per, 1.0 + z * np.sqrt(2.0 / (n * k))


def _retried(q1, x1, S, unseen, retry, w, per_window) -> tuple:
    """(x, S, unseen, what happened, simulations): the retry's point,
    refined on the first window, where it fits that window better than the
    complex's (then nothing is left reset: the point is not the complex's)."""
    lo, hi = np.array(q1.bounds_array, float).T
    try:
        xr, used = retry()
        xr = np.clip(np.asarray(xr, float), lo, hi)
        r = refine(q1, xr, max_evals=per_window, central=True, channel_weights=w, rel_step=STEP)
        used = int(used) + r.nfev
        Sr = float(r.f) if np.isfinite(r.f) else np.inf
    except Exception as exc:   # the complex's point stands
        log.warning("grow: the retry failed: %s", exc)
        used, Sr = 0, np.inf
    n = q1.samples.size
    taken = Sr < S
    log.info("grow: the complex's first window above the noise (%.3g per sample); the retry's %.3g: %s",
             S / n, Sr / n, "taken" if taken else "not taken")
    info = {"S_per_sample_complex": S / n, "S_per_sample_retry": Sr / n, "taken": bool(taken)}
    if taken:
        return np.asarray(r.x, float), Sr, [], info, used
    return x1, S, unseen, info, used


def _reset_unseen(q, x, w, S) -> tuple:
    """(x with the variables q cannot see at their start values, their
    names): see grow(reset_unseen=...)."""
    x0 = q.x0_vector()
    if x0 is None:
        return x, []
    x, out = np.array(x, float), []
    for i, (name, (lo, hi)) in enumerate(zip(q.free, q.bounds_array)):
        h = UNSEEN_STEP * (hi - lo)
        moved = []
        for xi in (min(x[i] + h, hi), max(x[i] - h, lo)):
            xt = x.copy()
            xt[i] = xi
            try:
                moved.append(abs(float(np.sum(tared(q.samples - q.simulate(xt), q.tare) ** 2 * w)) - S))
            except Exception:   # a point that does not simulate is seen
                moved.append(np.inf)
        if max(moved) < UNSEEN_DS:
            out.append(name)
    for name in out:
        i = q.free.index(name)
        x[i] = x0[i]
    if out:
        log.info("grow: %s unseen on the first window: back to their start values", ", ".join(out))
    return x, out


def _weights(q, x, noise_std) -> tuple:
    """(1 / sigma^2 per column, S at x): the noise declared or the residual's
    white part at x (a joint problem: its records' columns side by side, 7
    each); all ones and S infinite if x does not simulate."""
    try:
        r = tared(q.samples - q.simulate(x), q.tare)
    except Exception as exc:
        log.warning("grow: the first window's point does not simulate (%s): unweighted", exc)
        return np.ones(np.shape(q.samples)[1]), float("inf")
    sig = []
    for k in range(0, r.shape[1], len(FORCE_CHANNELS)):
        sig.append(noise_levels(r[:, k:k + len(FORCE_CHANNELS)], noise_std).sigma)
    w = 1.0 / np.concatenate(sig) ** 2
    return w, float(np.sum(r ** 2 * w))


__all__ = ["grow", "windows", "FIRST", "GROWTH"]
