"""Local refinement of an identification: Levenberg-Marquardt on the
objective's own residual (Eq. 10-12, tare included), with the Jacobian from
one-sided differences through the FMU (objective.jacobian).

Complex-RF finds the basin; on the release transient it then contracts onto
a ridge long before the minimum (docs/complex_rf.md). With an effect's
parameters in the design the residual is nearly linear in them (the
attribution's signatures are), so a few Gauss-Newton steps walk the rest of
the way that the complex cannot. A step is taken only if it lowers f; a
variable on its bound that would step out is held there (an active set) and
the step solved again for the others, the rest clipped.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Optional, Sequence, Union

import numpy as np

from ..objective.jacobian import demean_columns, jacobian, one_sided_jacobian, weights
from ..objective.problem import IdentificationProblem, tared
from ..objective.uncertainty import ROUGH, claimable_within, noise_level

log = logging.getLogger(__name__)


@dataclass
class Refined:
    x: np.ndarray
    f: float
    f_start: float
    nfev: int
    iterations: int
    sim: Optional[np.ndarray] = None   # the simulation at x (None if the start point failed)
    steps: Optional[np.ndarray] = None  # central: the difference steps the Jacobians used
    at: Optional[np.ndarray] = None     # central: where the last Jacobian was differenced (with `steps`; None
                                        # when it was updated by Broyden's formula after that)
    rough: tuple = ()                   # stop_rough: the watched variables found rough at the start (it
                                        # stopped there)
    short: bool = False                 # reach: stopped where its pace could not bring f down to `reach`


def _residual(problem: IdentificationProblem, x: np.ndarray, sw: np.ndarray) -> tuple:
    """(simulation, weighted tared residual, channels the tare demeans)."""
    sim = problem.simulate(x)
    r = problem.samples - sim
    demean = np.zeros(r.shape[1], bool)
    if problem.tare is not None:
        demean = np.abs(r.mean(axis=0)) <= problem.tare
    return sim, tared(r, problem.tare) * sw, demean


def refine(problem: IdentificationProblem, x, *, max_evals: int = 60, rel_step: float = 0.02,
           f_rtol: float = 1e-3, central: bool = False, channel_weights: Optional[np.ndarray] = None,
           steps: Optional[np.ndarray] = None, broyden: Union[bool, str] = False,
           stop_rough: Sequence[int] = (), within: Optional[float] = None,
           reach: Optional[float] = None) -> Refined:
    """Levenberg-Marquardt from x within the problem's bounds, at most
    `max_evals` simulations; stops when a step lowers f by less than `f_rtol`
    (relative) or no damping gives a lower f. A failed simulation ends it
    with the best point so far. `central`: the Jacobian by central
    differences (2 simulations per variable instead of 1: accurate to the
    bottom of a smooth bowl, where one-sided differences stall at about half
    their step). `channel_weights`: per channel, the metric minimised instead
    of the objective's 1 / (n span_j^2) (identification.loop.evidence: 1 / sigma_j^2,
    the likelihood's); f is then that weighted sum of squares. `steps`:
    central steps to scale from (Refined.steps of a neighbouring problem).
    `broyden`: after an accepted step the Jacobian is updated by Broyden's
    rank-one formula (in the variables scaled to their ranges) instead of
    differenced again, and the refinement stops where a step gains less than
    `f_rtol`; "refresh": such a step from an updated Jacobian has it
    differenced again first, and the refinement stops only where a step from
    a differenced one gains too little. `stop_rough` (central): variables
    whose column of the first Jacobian is rough (forward and backward
    differences part by ROUGH of their mean or more, at its step and again
    at half of it, as the intervals test it) stop the refinement there, at
    the start point (`rough` names them): on that window the response to
    them is chaotic, and no refinement makes the intervals call it smooth.
    `within`: the end (s) of the shorter window that follows; a rough column
    stops it only where that window could claim its variable
    (uncertainty.claimable_within on this Jacobian's rows), since a
    shorter window is taken for no other variable. `reach` (with `within`):
    the f below which the fit is at the declared noise
    (uncertainty.noise_bound; in the objective's own metric, so not with
    `channel_weights`). A window left above it is cut, and its
    refinement is thrown away with it. So the refinement stops once its
    average gain per iteration so far, kept up for every iteration the
    budget has left, would not bring f down to `reach` (`short`). A
    Levenberg-Marquardt refinement's gains shrink as it converges, so this
    pace overstates what is left, and the test errs towards going on."""
    if reach is not None and channel_weights is not None:
        raise ValueError("refine: `reach` is an f of the objective's own metric, not of `channel_weights`")
    x = np.array(x, float)
    lo, hi = np.array(problem.bounds_array, float).T
    sw = np.sqrt(weights(problem) if channel_weights is None else np.asarray(channel_weights, float))
    try:
        sim, r, demean = _residual(problem, x, sw)
    except Exception as exc:
        log.warning("refine: start point failed: %s", exc)
        return Refined(x, float("inf"), float("inf"), 1, 0)
    f = f_start = float(np.sum(r ** 2))
    nfev, it, lam = 1, 0, 1e-3
    per_jacobian = len(x) * (2 if central else 1)
    guess, steps = steps, None   # central: scaled to each variable's sensitivity at the start, kept after
    span = np.where(hi > lo, hi - lo, 1.0)
    raw, fresh = None, True   # the Jacobian's columns; whether they were differenced at x
    at = None
    per_iteration = (0 if broyden else per_jacobian) + 1   # at least: a Jacobian (unless updated) and one trial
    while nfev + (0 if not fresh else per_jacobian) + 1 <= max_evals:
        if fresh:
            if central:
                w = 1.0 / noise_level(problem.samples - sim) ** 2
                J, used, rough = jacobian(problem, x, sim, rel_step, w, steps, guess=guess)
                nfev += per_jacobian + (len(x) if steps is None else 0)
                steps = used
                raw = [J[:, :, k] for k in range(len(x)) if used[k] > 0]
                at = x.copy()
                if it == 0 and stop_rough:
                    chaotic, spent = _still_rough(problem, x, sim, w, used, rough, stop_rough)
                    nfev += spent
                    if chaotic and within is not None:
                        later = claimable_within(problem, J, problem.samples - sim, used, within)
                        chaotic = [k for k in chaotic if later[k]]
                    if chaotic:
                        log.info("refine: %s rough at the start: stopped there",
                                 ", ".join(problem.free[k] for k in chaotic))
                        return Refined(x, f, f_start, nfev, it, sim, steps, at, tuple(chaotic))
            else:
                raw = one_sided_jacobian(problem, x, sim, rel_step=rel_step)
                nfev += per_jacobian
        if len(raw) != len(x):
            break
        A = np.stack([(demean_columns(g, demean) * sw).ravel() for g in raw], axis=1)
        b = r.ravel()
        scale = np.sqrt(np.sum(A ** 2, axis=0))
        # a variable the objective does not see (all its effect within the tare) takes no step
        blind = scale <= 1e-9 * np.array([np.sqrt(np.sum((g * sw) ** 2)) for g in raw])
        scale = np.where(blind, 1.0, scale)
        As = np.where(blind, 0.0, A / scale)
        AtA, Atb = As.T @ As, As.T @ b
        it += 1
        better = False
        while nfev < max_evals:
            step = _bounded_step(AtA, Atb, lam, scale, x, lo, hi)
            xn = np.clip(x + step, lo, hi)
            nfev += 1
            try:
                sim_n, r_n, dm_n = _residual(problem, xn, sw)
                f_n = float(np.sum(r_n ** 2))
            except Exception as exc:
                log.warning("refine: simulation failed: %s", exc)
                f_n = float("inf")
            if f_n < f:
                gain = (f - f_n) / f
                if broyden:
                    raw = _broyden(raw, (xn - x) / span, sim_n - sim, span)
                    at = None
                x, sim, r, demean, f = xn, sim_n, r_n, dm_n, f_n
                lam = max(lam / 10.0, 1e-7)
                better = gain >= f_rtol
                break
            lam *= 10.0
            if lam > 1e4:
                break
        if not better:
            if broyden == "refresh" and not fresh:   # the updated Jacobian may be what stalls: difference it
                fresh, lam = True, 1e-3
                continue
            break
        fresh = not broyden
        if within is not None and reach is not None and f > reach:
            left = (max_evals - nfev) // per_iteration
            if f - (f_start - f) / it * left > reach:
                log.info("refine: f = %.4g after %d iterations, above the noise's %.4g, at %.3g an iteration for "
                         "the %d left: stopped (the window will be cut)", f, it, reach, (f_start - f) / it, left)
                return Refined(x, f, f_start, nfev, it, sim, steps, at, short=True)
    return Refined(x, f, f_start, nfev, it, sim, steps, at)


def _still_rough(problem, x, sim, w, used, rough, watch) -> tuple:
    """(the watched columns rough at their step and at half of it, the
    simulations spent): the intervals' test (uncertainty.ROUGH, recheck at
    half the step), the columns of the Jacobian itself left as they are."""
    first = [k for k in watch if not rough[k] < ROUGH]
    if not first:
        return [], 0
    half = np.where(np.isin(np.arange(len(x)), first), 0.5 * np.asarray(used, float), 0.0)
    _, _, again = jacobian(problem, x, sim, weights=w, steps=half, exact=False, only=first)
    return [k for k in first if not again[k] < ROUGH], 2 * len(first)


def _broyden(raw: list, z: np.ndarray, dy: np.ndarray, span: np.ndarray) -> list:
    """Columns of the Jacobian after Broyden's rank-one update for the step z
    (scaled to the ranges) that changed the simulation by dy: the least change
    (in the scaled variables) that makes J z = dy."""
    zz = float(z @ z)
    if not zz > 0:
        return raw
    G = np.stack(raw, axis=-1) * span          # d sim / d z
    G = G + np.multiply.outer(dy - G @ z, z) / zz
    return [G[..., k] / span[k] for k in range(len(raw))]


def _bounded_step(AtA, Atb, lam, scale, x, lo, hi) -> np.ndarray:
    """The damped Gauss-Newton step with the variables that sit on a bound
    and would step out of it held (an active set), solved again for the
    others. Clipping the full step instead moves the others as if the held
    one had moved too: on a correlated pair the clipped step is not a
    descent and the damping grows until the refinement stops short of the
    minimum on the bound (tests/test_refine.py: 0.20 for 0.99)."""
    n = len(x)
    free = np.ones(n, bool)
    for _ in range(n):
        step = np.zeros(n)
        k = np.flatnonzero(free)
        if k.size == 0:
            return step
        M = AtA[np.ix_(k, k)] + lam * np.eye(k.size)
        step[k] = np.linalg.solve(M, Atb[k]) / scale[k]
        out = free & (((x <= lo) & (step < 0)) | ((x >= hi) & (step > 0)))
        if not out.any():
            return step
        free &= ~out
    return step
