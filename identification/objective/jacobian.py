"""The Jacobian of an identification problem's simulation, one module for
every use of it:

- `jacobian`: central differences, each step scaled to its variable's
  sensitivity, with the roughness of each column (the intervals'; where
  forward and backward differences disagree the objective is not smooth);
- `one_sided_jacobian`: one-sided differences of a fixed share of each bound
  range, towards the inside of the bounds (Levenberg-Marquardt's and the
  closed loop's: half the simulations, no roughness needed);
- `weights`: the metric per channel the objective sums the residual in;
- `demean_columns`: a column as the tare sees it.
"""
from __future__ import annotations

import logging
from typing import Optional

import numpy as np

from .parallel import Failed, simulate_all
from .problem import EXACT_STEP, IdentificationProblem

log = logging.getLogger(__name__)

REL_STEP = 0.02                # difference step, of the bound range: the response to it stands well
                               # above the solver's error at the transient tolerance (lss_fmu.protocol)
RESPONSE = 5.0                 # the change a difference step aims at, in noise levels
MIN_STEP, MAX_STEP = 1e-7, 0.05  # the limits of a difference step, of the bound range


def exact_columns(problem, x: np.ndarray) -> dict:
    """{k: d simulation / d x_k} of the free variables the FMU differentiates
    itself (the problem's exact_indices: its forward sensitivities, one run
    for all); {} where the problem does not ask for them or cannot have them,
    or if that run failed (logged: the columns are then differenced)."""
    ks = problem.exact_indices() if hasattr(problem, "exact_indices") else ()
    if not ks:
        return {}
    try:
        return problem.simulate_exact(x, ks)[1]
    except Exception as exc:
        log.warning("the FMU's sensitivities failed (%s); the columns are differenced", exc)
        return {}


def jacobian(problem: IdentificationProblem, x: np.ndarray, sim0: np.ndarray,
             rel_step: float = REL_STEP, weights: Optional[np.ndarray] = None,
             steps: Optional[np.ndarray] = None, guess: Optional[np.ndarray] = None,
             recheck: Optional[float] = None, exact: bool = True, only=None) -> tuple:
    """(J as (n_samples, n_channels, n_free), the steps used, the roughness of
    each column): central differences inside the bounds, one-sided at a bound;
    the roughness is |forward - backward| / |their mean| in the metric
    `weights` per channel (at a bound: of two successive steps inwards); a
    failed run leaves a zero column and an infinite roughness.

    Each step is scaled to its variable's sensitivity unless `steps` are
    given: a first step of `rel_step` of the bound range is shortened or
    lengthened until the simulation moves by about RESPONSE in the metric of
    `weights` (a few noise levels: far above the solver's error, far below the
    nonlinearity of a variable the record pins to a thousandth of its range,
    such as the pretension). `guess`: first steps to scale from instead of
    `rel_step` of the range (the steps of a neighbouring window: most need
    no rescaling there). `recheck`: a column at least this rough is measured
    again at half its step (2 simulations more), which tells the curvature
    of a smooth response (the disagreement halves) from chaos (it stays).

    The simulations run in rounds (each column's first step, its rescaled
    steps, its second step), side by side on the problem's pool when it has
    one (identification.objective.parallel): the same points either way.

    `only`: the columns to difference (the others stay zero, their step 0).

    `exact`: where the problem asks for them (its `sensitivities`), the
    columns the FMU can differentiate itself come from its forward
    sensitivities instead (exact_columns: smooth, roughness 0, their step the
    followers' tiny one); the others are differenced as above."""
    lo, hi = np.array(problem.bounds_array, float).T
    wt = np.ones(sim0.shape[1]) if weights is None else np.asarray(weights, float)
    n = len(x)
    J = np.zeros(sim0.shape + (n,))
    used = np.zeros(n)
    rough = np.zeros(n)

    def norm(a):
        return float(np.sqrt(np.sum(a ** 2 * wt)))

    def at(k, h):
        xh = np.array(x, float)
        xh[k] += h
        return xh

    def run(points: dict) -> dict:
        """Column -> simulation at its point, one round (side by side on the problem's pool)."""
        ys = simulate_all(problem, list(points.values()), base=(x, sim0))
        out = {}
        for k, y in zip(points, ys):
            if isinstance(y, Failed):   # the variable then counts as not identifiable
                log.warning("jacobian column %s failed: %s", problem.free[k], y.message)
                rough[k] = np.inf
            else:
                out[k] = y
        return out

    span = hi - lo
    known = exact_columns(problem, x) if exact else {}
    for k, col in known.items():
        J[:, :, k] = col
        used[k] = EXACT_STEP * span[k]
    todo = [k for k in range(n) if k not in known and (only is None or k in only)]
    first = steps if steps is not None else guess
    # a carried step at or below the followers' on a column the core can give is that column's last exact step
    # (its run failed this time): no step to difference with
    followed = set(problem.exact_indices()) if hasattr(problem, "exact_indices") else set()
    h = np.array([float(first[k]) if first is not None and first[k] > 0
                  and not (k in followed and first[k] <= EXACT_STEP * span[k]) else rel_step * span[k]
                  for k in range(n)])
    sgn = np.where(x + h <= hi, 1.0, -1.0)
    y1 = run({k: at(k, sgn[k] * h[k]) for k in todo})
    if steps is None:
        for _ in range(3):   # scale each step to the response (linear guess), at most 3 tries
            again = {}
            for k, y in y1.items():
                resp = norm(y - sim0)
                if 0.25 * RESPONSE <= resp <= 4.0 * RESPONSE or resp == 0:
                    continue
                h[k] = float(np.clip(h[k] * RESPONSE / resp, MIN_STEP * span[k], MAX_STEP * span[k]))
                sgn[k] = 1.0 if x[k] + h[k] <= hi[k] else -1.0
                again[k] = at(k, sgn[k] * h[k])
            if not again:
                break
            for k in again:
                del y1[k]
            y1.update(run(again))
    central = {k for k in y1 if sgn[k] > 0 and x[k] - h[k] >= lo[k]}

    def second(ks, hs):
        """The second point of each column k: backward, or a second step inwards at a bound."""
        return run({k: at(k, -hs[k]) if k in central else at(k, 2 * sgn[k] * hs[k]) for k in ks})

    def column(k, hk, ya, yb):
        """(column, roughness) of variable k from its two points at step hk."""
        if k in central:
            fwd, bwd = (ya - sim0) / hk, (sim0 - yb) / hk
            col = 0.5 * (fwd + bwd)
            m = norm(col)
            return col, (norm(fwd - bwd) / m if m > 0 else np.inf)
        d1 = sgn[k] * (ya - sim0) / hk     # at a bound: two steps inwards, their differences compared
        d2 = sgn[k] * (yb - ya) / hk
        m = norm(0.5 * (d1 + d2))
        return d1, (norm(d1 - d2) / m if m > 0 else np.inf)

    y2 = second(sorted(y1), h)
    for k in sorted(y2):
        J[:, :, k], rough[k] = column(k, h[k], y1[k], y2[k])
        used[k] = h[k]
    if recheck is not None:
        # a smooth simulation's forward and backward differences part by its curvature, in proportion
        # to the step; a chaotic one's do not come together: a rough column is measured again at half
        # the step and keeps what it shows there
        again = [k for k in sorted(y2) if np.isfinite(rough[k]) and rough[k] >= recheck]
        half = {k: 0.5 * h[k] for k in again}
        ya = run({k: at(k, sgn[k] * half[k]) for k in again})
        yb = second(sorted(ya), half)
        for k in sorted(yb):
            J[:, :, k], rough[k] = column(k, half[k], ya[k], yb[k])
            used[k] = half[k]
            log.debug("jacobian column %s measured again at half the step: roughness %.3g",
                      problem.free[k], rough[k])
    return J, used, rough


def one_sided_jacobian(problem: IdentificationProblem, x: np.ndarray, sim0: np.ndarray,
                  rel_step: float = REL_STEP) -> list:
    """One-sided differences of the simulation in each free variable, towards the
    inside of the bounds (the FMU's sensitivities where it has them, see
    exact_columns); a failed run gives no column."""
    known = exact_columns(problem, x)
    steps, points, ks = [], [], []
    for k, (lo, hi) in enumerate(problem.bounds_array):
        if k in known:
            continue
        h = rel_step * (hi - lo)
        if x[k] + h > hi:
            h = -h
        xk = np.array(x, float)
        xk[k] += h
        steps.append(h)
        points.append(xk)
        ks.append(k)
    cols = dict(known)
    for k, h, y in zip(ks, steps, simulate_all(problem, points, base=(x, sim0))):
        if isinstance(y, Failed):
            log.warning("base column %s failed: %s", problem.free[k], y.message)
        else:
            cols[k] = (y - sim0) / h
    return [cols[k] for k in sorted(cols)]


def weights(problem: IdentificationProblem) -> np.ndarray:
    """Per channel: f = sum_j w_j sum_t r_tj^2 (Eq. 10-12, or the likelihood's 1 / (n sigma_j^2))."""
    if getattr(problem, "objective", "pointwise") == "likelihood":
        return 1.0 / (len(problem.times) * problem.noise ** 2)
    span = problem.samples.max(axis=0) - problem.samples.min(axis=0)
    span = np.where(span > 0, span, 1.0)
    return 1.0 / (len(problem.times) * span ** 2)


def demean_columns(g: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """g with the mean of each masked channel (column) taken out: what the tare does to a residual."""
    if not mask.any():
        return g
    g = np.array(g, float)
    g[:, mask] -= g[:, mask].mean(axis=0)
    return g
