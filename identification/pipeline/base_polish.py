"""The base model at its own optimum before the closed loop tests anything
(issue 18): the complex again, Levenberg-Marquardt in the likelihood's
metric, and the profile of its least-determined variable."""
from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Optional

import numpy as np

from ..objective.jacobian import one_sided_jacobian
from ..objective.problem import IdentificationProblem, tared, weighted_residual
from .identify import identify
from .refine import refine

log = logging.getLogger(__name__)

BASE_REFINE_EVALS = 60   # simulations of the base's refinement to its own optimum
PROFILE_POINTS = 9       # the base's least-determined variable scanned at this many values ...
PROFILE_EVALS = 24       # ... the others refitted with this many simulations at each (profile_polish) ...
ZOOM_EVALS = 8           # ... then Brent's method around the best value, at most this many profile points
SEEN = 1.0               # a variable whose whole bound range moves S (linearised) by less than this, one chi^2
                         # unit, is not seen by the record: the profile does not scan it
STEP = 0.003             # difference step of the refinements, of each bound range: the CoR landscape is rough
                         # and its valleys narrow (e_SW to 0.005): 0.02 leads Levenberg-Marquardt astray


def polish_base(base: IdentificationProblem, x: np.ndarray, sim: np.ndarray, w: np.ndarray, *, seed: int,
                polish_evals: int, base_refine_evals: int, profile_points: int,
                journal: Optional[Path] = None) -> tuple:
    """The base at its own optimum, in the likelihood's metric (w = 1 / sigma^2
    per channel), before anything is tested: a base that stopped above the
    noise floor would hand its remainder to any flexible candidate. The
    complex again from x with `polish_evals` (what an extension gets), then
    Levenberg-Marquardt to the bottom of its basin, then the profile of the
    least-determined variable (profile_polish). Returns (x, sim, info)."""
    r0 = tared(base.samples - sim, base.tare)
    S0 = float(np.sum(r0 ** 2 * w))
    base_refined = {"S_start": S0, "S": S0, "nfev": 0}
    if polish_evals > 0:
        # the base gets what an extension gets: the complex from its point with the same budget ...
        pol = identify(dataclasses.replace(base, x0=base.values(x)), max_evals=max(polish_evals, len(base.free) + 3),
                       seed=seed + 101, progress=False, journal=journal)
        base_refined["complex_evals"] = int(pol.nfev) if hasattr(pol, "nfev") else polish_evals
        try:
            sim_p = base.simulate(pol.x)
            rp = tared(base.samples - sim_p, base.tare)
            if float(np.sum(rp ** 2 * w)) < S0:
                x, sim, S0 = np.asarray(pol.x, float), sim_p, float(np.sum(rp ** 2 * w))
        except Exception as exc:
            log.warning("base polish failed: %s", exc)
        base_refined["S_complex"] = S0
    if base_refine_evals > 0:
        # ... and Levenberg-Marquardt in the likelihood's metric to the bottom of its basin
        ref = refine(base, x, max_evals=base_refine_evals, central=True, channel_weights=w, rel_step=STEP)
        base_refined.update({"S": min(S0, ref.f), "nfev": ref.nfev, "iterations": ref.iterations})
        if ref.f < S0 and ref.sim is not None:
            x, sim = np.asarray(ref.x, float), ref.sim
    if profile_points > 1:
        try:
            xp, Sp, base_refined["profile"] = profile_polish(base, x, w, points=profile_points)
            if Sp < base_refined["S"]:
                x, sim = xp, base.simulate(xp)
                base_refined["S"] = Sp
        except Exception as exc:
            log.warning("profile polish failed: %s", exc)
    return x, sim, base_refined


def profile_polish(base: IdentificationProblem, x: np.ndarray, w: np.ndarray, *, points: int = PROFILE_POINTS,
                   evals: int = PROFILE_EVALS) -> tuple:
    """The base's least-determined variable (the smallest sensitivity over its
    bound range, in the likelihood's metric: e_JR on the release transient,
    twenty times weaker than the other CoRs and many-valleyed) scanned over its
    range, the others refitted at each value (Levenberg-Marquardt, `evals`
    simulations); the best then refined with everything free. Returns (x, S,
    info); x is the start when nothing is lower.

    Only a variable the record sees is scanned (its whole range moves S by
    SEEN or more): a start-stop's first 0.3 s, the drive saturated, does not
    see the set point or the gains at all, and a scan over one of them would
    only repeat the others' fit at every value. Nothing seen, nothing
    scanned."""
    x = np.asarray(x, float)
    sim0 = base.simulate(x)
    _, S_start = weighted_residual(base, sim0, w)
    info = {"S_start": S_start, "S": S_start}
    if len(base.free) < 2 or points < 2:
        return x, S_start, info
    cols = one_sided_jacobian(base, x, sim0)
    if len(cols) != len(x):
        return x, S_start, info
    lo, hi = np.array(base.bounds_array, float).T
    sens = np.array([math.sqrt(float(np.sum(g ** 2 * w))) * (hi[k] - lo[k]) for k, g in enumerate(cols)])
    seen = np.flatnonzero(sens >= SEEN)
    if seen.size == 0:
        info["nfev"] = len(x) + 1
        return x, S_start, info
    k = int(seen[np.argmin(sens[seen])])
    name = base.free[k]
    others = tuple(n for n in base.free if n != name)
    best = (S_start, x)
    count = {"nfev": len(x) + 1}
    xs0 = np.array([xv for n, xv in zip(base.free, x) if n != name])

    def profile(v):
        """S with `name` at v, the others refitted (from the start's values)."""
        q = dataclasses.replace(base, free=others, x0={**base.values(x), name: float(v)})
        try:
            r = refine(q, xs0, max_evals=evals, central=False, channel_weights=w, rel_step=STEP)
        except Exception as exc:
            log.warning("profile of %s at %g failed: %s", name, v, exc)
            return math.inf, None
        count["nfev"] += r.nfev
        vals = q.values(r.x)
        return r.f, np.array([vals[n] for n in base.free])

    grid = np.linspace(lo[k], hi[k], points)
    values = []
    for v in grid:
        f, xv = profile(v)
        values.append(f)
        if f < best[0]:
            best = (f, xv)
    # the valley can be narrower than the grid: Brent's method within a grid step of the best point
    i = int(np.argmin(values))
    if np.isfinite(values[i]):
        from scipy.optimize import minimize_scalar
        step = grid[1] - grid[0]
        found = {}

        def f1(v):
            fv, xv = profile(v)
            found[v] = (fv, xv)
            return fv
        minimize_scalar(f1, bounds=(max(lo[k], grid[i] - step), min(hi[k], grid[i] + step)), method="bounded",
                        options={"xatol": 2e-3 * (hi[k] - lo[k]), "maxiter": ZOOM_EVALS})
        for fv, xv in found.values():
            if xv is not None and fv < best[0]:
                best = (fv, xv)
    nfev = count["nfev"]
    info.update({"variable": name, "points": points, "nfev": nfev, "S_profile": best[0]})
    if best[0] < S_start:
        r = refine(base, best[1], max_evals=BASE_REFINE_EVALS, central=True, channel_weights=w, rel_step=STEP)
        info["nfev"] = nfev + r.nfev
        xb, Sb = (np.asarray(r.x, float), r.f) if r.f < best[0] else (best[1], best[0])
        info["S"] = Sb
        return xb, Sb, info
    return x, S_start, info
