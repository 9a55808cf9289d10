"""Settling a provisional effect at the end of the loop (issue 18).

An effect that passed every test while the model with it stayed above the
noise is held provisional (verdict.decide): it may be the first of two
effects, or a wrong effect that took a share of a missing one's misfit. It
is confirmed once a later round's model, which carries it, reaches the
noise; but a later effect can explain what the provisional one took (a bump
held in round 1 for a small joint play that round 2 then finds). So before
it is confirmed it is switched off in the final model, the rest refitted,
and it must still be needed there: the misfit must rise by a decisive BIC
difference (rivals.DECISIVE) for the parameters it adds, scaled by its own
test's correlated-residual factor.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from typing import Callable, Optional, Sequence

import numpy as np
from scipy import stats

from ..pipeline.base_polish import STEP
from .loop_result import Round
from ..objective.problem import weighted_residual
from ..pipeline.refine import refine
from .rivals import DECISIVE

log = logging.getLogger(__name__)

REFIT_EVALS = 60   # Levenberg-Marquardt simulations for the final model with the effect switched off


def final_model(last: Round) -> tuple:
    """(problem, x) of the loop's last model: the last round's extension if it
    was confirmed, else that round's refitted base."""
    if last.confirmed and not last.provisional and last.problem_extended is not None:
        return last.problem_extended, np.asarray(last.x_extended, float)
    return last.base_problem, np.asarray(last.x_base, float)


def switched_off_in(problem, x, names) -> tuple:
    """(problem, x) with the parameters `names` removed (the FMU's defaults:
    the effect off) and the rest at their values in x."""
    vals = problem.values(x)
    drop = set(names)
    off = dataclasses.replace(problem, free=tuple(n for n in problem.free if n not in drop),
                              fixed={k: v for k, v in problem.fixed.items() if k not in drop},
                              x0={k: v for k, v in (problem.x0 or {}).items() if k not in drop})
    return off, np.array([vals[n] for n in off.free], float)


def still_needed(r: Round, last: Round, *, refit_evals: int = REFIT_EVALS) -> Optional[dict]:
    """Round r's effect switched off in the final model, the rest refitted:
    {"dS", "dbic", "p", "needed", "text"}; None when it cannot be evaluated
    (then the effect is settled as before)."""
    names = list(r.identified)
    if not names or last.noise is None:
        return None
    try:
        problem, x = final_model(last)
        w = 1.0 / np.asarray(last.noise.sigma, float) ** 2
        _, S = weighted_residual(problem, problem.simulate(x), w)
        off, x_off = switched_off_in(problem, x, names)
        if refit_evals > 0 and len(off.free):
            rb = refine(off, x_off, max_evals=refit_evals, central=True, channel_weights=w, rel_step=STEP)
            if np.isfinite(rb.f):
                x_off = np.asarray(rb.x, float)
        _, S_off = weighted_residual(off, off.simulate(x_off), w)
    except Exception as exc:   # the loop's result stands without this check
        log.warning("round %d's effect switched off in the final model cannot be evaluated: %s", r.number, exc)
        return None
    q = max(1, len([n for n in names if n in problem.free]))
    ev = r.evidence
    a = max(1.0, float(ev.lr.scale)) if ev is not None and ev.lr is not None else 1.0
    N = max(2, int(problem.samples.size))
    dS = float(S_off - S)
    dbic = dS / a - q * math.log(N)
    p = float(stats.chi2.sf(max(dS, 0.0) / a, q))
    needed = dbic >= DECISIVE
    text = (f"switched off in the final model with the rest refitted, S rises by {dS:.1f} (scale {a:.2f}, "
            f"{q} parameter(s): p = {p:.2g}, dBIC {dbic:+.1f})")
    return {"dS": dS, "dbic": float(dbic), "p": p, "needed": bool(needed), "text": text}


def settle_provisional(rounds: Sequence[Round],
                       needed: Optional[Callable[[Round, Round], Optional[dict]]] = None) -> None:
    """A provisional effect is confirmed when the last round's model, which
    carries it, reaches the noise (that round confirmed an effect at the
    noise, or found nothing significant above it) and, with `needed`
    (still_needed), it is still needed in that model; otherwise it stays
    unconfirmed."""
    if not rounds:
        return
    last = rounds[-1]
    at_noise = (last.confirmed and not last.provisional) or last.outcome == "nothing significant"
    for r in rounds:
        if not r.provisional:
            continue
        if not (at_noise and r is not last):
            r.verdict += "; no later round brought the model to the noise"
            continue
        check = needed(r, last) if needed is not None else None
        if check is not None:
            r.refined["settled"] = check
            if not check["needed"]:
                r.verdict += (f"; round {last.number}'s model reaches the noise, but the effect is not needed "
                              f"in it: {check['text']}")
                continue
        r.confirmed, r.outcome = True, "confirmed"
        r.verdict = (f"{r.verdict_if_confirmed}; with the effect of round {last.number} the model reaches "
                     f"the noise" if last.confirmed else
                     f"{r.verdict_if_confirmed}; at the next round's refitted base the residual is at the noise")
        if check is not None:
            r.verdict += f"; still needed there: {check['text']}"


__all__ = ["REFIT_EVALS", "final_model", "settle_provisional", "still_needed", "switched_off_in"]
