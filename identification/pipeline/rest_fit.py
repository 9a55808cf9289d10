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
the pretension alone (a scan over its bounds, then a local fit), the scan of
each trigger point, then all together.
The valleys' places move with the pretension (on a layout-5 record, 5 % of
pretension moved the deepest valley 0.45 m, from the truth's to one S per
sample 6 times higher), so where the joint fit leaves a record off the
noise its trigger point is scanned again at the pretension that fit found.
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
from ..objective.uncertainty import at_noise
from .base_polish import STEP
from .refine import refine
from .windowing import truncated

log = logging.getLogger(__name__)

COARSE = 41    # trigger points tried over the trigger's bounds ...
FINE = 11      # ... then over two coarse steps around the best
REST_COARSE = 21   # fit_rest's grid (0.05 m on the usual 1 m bounds, its Levenberg-Marquardt the fine step)
SHARED_COARSE = 41  # fit_rest's grid of the pretension (2.5 % of the nominal on the usual bounds, half to 1.5 x it)
ROUNDS = 3         # fit_rest's scans of the trigger points at most, each at the pretension fitted before
OFF_Z = 3.0        # a record off the noise: this many sd of chi^2 above its mean, no margin (growing's retry)


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
    the pretension scanned over its bounds and Levenberg-Marquardt on it
    from the best, each trigger point scanned, then Levenberg-Marquardt on
    all of them; then, while that leaves a record off
    the noise, its trigger point scanned again at the pretension fitted
    (moved only to a deeper valley) and Levenberg-Marquardt on all again,
    ROUNDS scans in all, stopping where no trigger point moves.
    `channel_weights`: the metric (1 / sigma^2 per column, a joint problem's
    records side by side), else the objective's. Where a fit fails, the
    values before it stand."""
    qr = only(q, rest)
    vals = dict(zip(qr.free, map(float, qr.x0_vector())))
    if TRIGGER not in qr.free:
        used = _scan_shared(qr, vals, channel_weights)
        vals, more = _levenberg_marquardt(qr, vals, channel_weights, max_evals)
        return vals, used + more
    # the pretension first, the trigger points where they are: where the chain stands moves S by valleys,
    # but the valleys' places depend on the pretension (on a layout-2 record the scan at the bounds' middle
    # pretension put one trigger point 0.37 m off)
    shared = [n for n in qr.free if n != TRIGGER and "@" not in n]
    used = 0
    if shared:
        qs = only(without(qr, (), vals), shared)
        used = _scan_shared(qs, vals, channel_weights)
        got, more = _levenberg_marquardt(qs, {n: vals[n] for n in shared}, channel_weights, max_evals)
        vals.update(got)
        used += more
    parts = qr.parts if isinstance(qr, JointProblem) else [qr]
    scanned = dict.fromkeys(range(len(parts)))   # record -> its S per sample where known
    for round_ in range(ROUNDS):
        # each round after the first scans at the pretension the joint fit left, the records it leaves off
        # the noise, and moves a trigger point only to a deeper valley: a pretension 5 % off moves a
        # trigger point's best valley by decimetres (on one layout-5 record 0.45 m)
        moved, n = _scan(parts, scanned, vals, channel_weights, deeper_only=round_ > 0)
        used += n
        if round_ > 0 and not moved:
            break
        vals, more = _levenberg_marquardt(qr, vals, channel_weights, max_evals)
        used += more
        if round_ == ROUNDS - 1:
            break
        scanned, n = _off_noise(parts, vals, channel_weights)
        used += n
        if not scanned:
            break
    return vals, used


def _scan_shared(qs, vals: dict, channel_weights) -> int:
    """Simulations: each free variable of qs (the pretension) put where
    SHARED_COARSE points over its bounds fit qs's window best, the others at
    `vals`, which it updates. S along the pretension is rough on a scale of
    1 % (Levenberg-Marquardt from a nominal 7 % off stopped 6 % off) but
    falls to one valley on the 2.5 % grid, with the trigger points at
    their marks."""
    w = weights(qs) if channel_weights is None else np.asarray(channel_weights, float)
    used = 0
    for name in qs.free:
        lo, hi = qs.bounds[name]
        best, S_best = vals[name], np.inf
        for v in np.linspace(lo, hi, SHARED_COARSE):
            x = np.array([v if n == name else vals[n] for n in qs.free])
            used += 1
            try:
                S = weighted_residual(qs, qs.simulate(x), w)[1]
            except Exception:   # a point that does not simulate is infinitely far
                continue
            if S < S_best:
                best, S_best = float(v), S
        vals[name] = best
    return used


def _block(parts, k: int, channel_weights) -> np.ndarray:
    """Record k's metric: its columns of `channel_weights`, else its objective's weights."""
    width = len(FORCE_CHANNELS)
    return weights(parts[k]) if channel_weights is None else \
        np.asarray(channel_weights, float)[k * width:(k + 1) * width]


def _on_trigger(part, vals: dict):
    """One record with its trigger point alone free, the shared rest values of `vals` held."""
    shared = {n: v for n, v in vals.items() if "@" not in n and n != TRIGGER}
    return dataclasses.replace(part, free=(TRIGGER,), x0={**(part.x0 or {}), **shared})


def _record_S(part, k: int, vals: dict, w: np.ndarray) -> float:
    """Record k's S per sample at `vals` in the metric w (infinite where it does not simulate)."""
    pk = _on_trigger(part, vals)
    try:
        return weighted_residual(pk, pk.simulate(np.array([vals[own(k)]])), w)[1] / pk.samples.size
    except Exception:
        return np.inf


def _scan(parts, ks, vals: dict, channel_weights, deeper_only: bool) -> tuple:
    """(records whose trigger point moved, simulations): each record of `ks`
    ({record: its S per sample at `vals`, None where not known}) scanned
    (trigger_scan) with the shared values of `vals`, its value in `vals` set
    to the scan's best; `deeper_only`: only where the best lies in another
    valley (more than a grid step away) and fits better than the value
    there."""
    moved, used = [], 0
    for k, S_now in ks.items():
        part, w = parts[k], _block(parts, k, channel_weights)
        pk = _on_trigger(part, vals)
        lo, hi = pk.bounds[TRIGGER]
        s, S, n = trigger_scan(pk, {TRIGGER: vals[own(k)]}, w, float(pk.times[-1] - pk.times[0]),
                               coarse=REST_COARSE, fine=0)
        used += n
        if not np.isfinite(S):   # no point simulated: the value before stands
            continue
        if deeper_only:
            if S_now is None:
                S_now, used = _record_S(part, k, vals, w), used + 1
            if abs(s - vals[own(k)]) <= (hi - lo) / (REST_COARSE - 1) or S >= S_now:
                continue
        vals[own(k)] = s
        moved.append(k)
    return moved, used


def _off_noise(parts, vals: dict, channel_weights) -> tuple:
    """({record off the noise at `vals`: its S per sample}, simulations):
    off by uncertainty.at_noise's test in the declared noise's metric, OFF_Z
    sd and no margin; without that metric (no `channel_weights`, or not the
    likelihood objective) every record, as none can be said at the noise."""
    if channel_weights is None:
        return dict.fromkeys(range(len(parts))), 0
    off = {}
    for k, part in enumerate(parts):
        S = _record_S(part, k, vals, _block(parts, k, channel_weights))
        if at_noise(part, S * np.shape(part.samples)[1], z=OFF_Z, margin=0.0) is not True:
            off[k] = S
    return off, len(parts)


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
