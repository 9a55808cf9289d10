"""What sets the chain at rest, fitted before a global search.

A record from rest relaxes its chain again for every value of the pretension
and of its trigger point (where the chain stands), and the relaxation costs
more than the first window that follows it (2.6 s of relaxation for 0.3 s of
window on the 685-cart layout). A complex that holds them leaves each record
one relaxed chain for all its candidates, and is worth as much as the values
held are near the truth. They can be fitted first, with the CoRs at their
start values: the forces before and during the start-up are set by the chain
at rest much more than by its impacts (on a layout-2 record, S along the
trigger point is the same to 1 % with the CoRs at the truth or 0.2 off).

`trigger_scan` finds one record's trigger point on a grid over its bounds:
S is periodic in it with the carts' pitch (valleys about 0.1 m wide on that
record), so a local fit from the marks' value finds the nearest valley, not
the deepest. `fit_rest` fits the pretension and every record's trigger point:
the pretension alone, the scan of each trigger point, then all together.
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Mapping, Sequence

import numpy as np

from lss_fmu.design import TRIGGER
from lss_fmu.variables import FORCE_CHANNELS

from ..objective.jacobian import weights
from ..objective.joint import JointProblem, own
from ..objective.problem import weighted_residual
from .base_polish import STEP
from .refine import refine
from .windowing import truncated

log = logging.getLogger(__name__)

COARSE = 41    # trigger points tried over the trigger's bounds ...
FINE = 11      # ... then over two coarse steps around the best
REST_COARSE = 21   # fit_rest's grid (0.05 m on the usual 1 m bounds, its Levenberg-Marquardt the fine step)


def trigger_scan(part, values: dict, w: np.ndarray, first: float, *, coarse: int = COARSE,
                 fine: int = FINE) -> tuple:
    """(trigger point, S per sample there, simulations): the trigger point of
    `part` (one record) that fits its first `first` seconds best, the other
    design variables at `values`, S in the metric `w` (1 / sigma^2 per
    channel): `coarse` points over the bounds, then `fine` over two coarse
    steps around the best (0: none). A point that does not simulate counts as
    infinitely far."""
    q = truncated(part, part.times[0] + first)
    lo, hi = q.bounds[TRIGGER]
    k = q.free.index(TRIGGER)
    base = np.array([values[n] for n in q.free], float)

    def S(s: float) -> float:
        x = base.copy()
        x[k] = s
        try:
            return weighted_residual(q, q.simulate(x), w)[1]
        except Exception:
            return np.inf
    grid = np.linspace(lo, hi, coarse)
    vals = [S(s) for s in grid]
    best = int(np.argmin(vals))
    s_best, S_best = grid[best], vals[best]
    if fine > 0:
        h = grid[1] - grid[0] if coarse > 1 else 0.0
        grid_f = np.linspace(max(lo, grid[best] - h), min(hi, grid[best] + h), fine)
        fvals = [S(s) for s in grid_f]
        j = int(np.argmin(fvals))
        if fvals[j] <= S_best:
            s_best, S_best = grid_f[j], fvals[j]
    return float(s_best), float(S_best) / q.samples.size, coarse + max(int(fine), 0)


def fit_rest(q, rest: Sequence[str], channel_weights, max_evals: int) -> tuple:
    """({name: value} of `rest`, evaluations: Levenberg-Marquardt's of q, the
    scan's of one record each): the variables of `rest` (the
    pretension, the trigger points: growing.at_rest) fitted on q's window
    with every other variable at its start value (module docstring):
    Levenberg-Marquardt on the pretension, each trigger point scanned, then
    Levenberg-Marquardt on all of them.
    `channel_weights`: the metric (1 / sigma^2 per column, a joint problem's
    records side by side), else the objective's. Where a fit fails, the
    values before it stand."""
    qr = only(q, rest)
    vals = dict(zip(qr.free, map(float, qr.x0_vector())))
    if TRIGGER not in qr.free:
        return _levenberg_marquardt(qr, vals, channel_weights, max_evals)
    # the pretension first, the trigger points where they are: where the chain stands moves S by valleys,
    # but the valleys' places depend on the pretension (on a layout-2 record the scan at the bounds' middle
    # pretension put one trigger point 0.37 m off)
    shared = [n for n in qr.free if n != TRIGGER and "@" not in n]
    used = 0
    if shared:
        got, used = _levenberg_marquardt(only(without(qr, (), vals), shared), {n: vals[n] for n in shared},
                                         channel_weights, max_evals)
        vals.update(got)
    parts = qr.parts if isinstance(qr, JointProblem) else [qr]
    width = len(FORCE_CHANNELS)
    shared = {n: v for n, v in vals.items() if "@" not in n and n != TRIGGER}
    for k, part in enumerate(parts):
        w = weights(part) if channel_weights is None else \
            np.asarray(channel_weights, float)[k * width:(k + 1) * width]
        pk = dataclasses.replace(part, free=(TRIGGER,), x0={**(part.x0 or {}), **shared})
        span = float(pk.times[-1] - pk.times[0])
        s, S, n = trigger_scan(pk, {TRIGGER: vals[own(k)]}, w, span, coarse=REST_COARSE, fine=0)
        used += n
        if np.isfinite(S):   # else no point simulated: the value before stands
            vals[own(k)] = s
    vals, more = _levenberg_marquardt(qr, vals, channel_weights, max_evals)
    return vals, used + more


def only(q, names: Sequence[str]):
    """q with only `names` free (a joint problem's records' own trigger points
    follow its first's)."""
    if isinstance(q, JointProblem):
        return JointProblem(q.parts, free=[n for n in q.free if n in names and "@" not in n], x0=q.x0,
                            name=q.name)
    return dataclasses.replace(q, free=tuple(n for n in q.free if n in names))


def without(q, names: Sequence[str], values: Mapping[str, float] = None):
    """q with `names` no longer free: at `values`, else at q's start values (a
    joint problem's trigger points go together, as its records' own ones
    follow the first's)."""
    x0 = {**(q.x0 or {}), **dict(values or {})}
    if isinstance(q, JointProblem):
        return JointProblem(q.parts, free=[n for n in q.free if n not in names and "@" not in n], x0=x0,
                            name=q.name)
    return dataclasses.replace(q, free=tuple(n for n in q.free if n not in names), x0=x0)


def _levenberg_marquardt(qr, vals: dict, channel_weights, max_evals: int) -> tuple:
    """(values, simulations): Levenberg-Marquardt on qr from `vals`."""
    x0 = np.array([vals[n] for n in qr.free])
    try:
        r = refine(qr, x0, max_evals=max_evals, central=True, channel_weights=channel_weights, rel_step=STEP)
    except Exception as exc:   # the values before stand
        log.warning("fit_rest: Levenberg-Marquardt failed: %s", exc)
        return vals, 0
    x = np.asarray(r.x, float) if np.isfinite(r.f) else x0
    return dict(zip(qr.free, map(float, x))), int(r.nfev)
