"""An effect probed on a ladder (the joint play: catalogue.JointClearance) is
extended within one rung, where its landscape is a single valley. The rung is
the linear ranking's pick at the base's CoRs, and the base's CoRs have
absorbed whatever part of the effect their own signatures share with it; the
pick is then biased towards a smaller size, and the extension can end on its
rung's upper bound with the misfit still falling across it (the size and
the CoRs move together there). The rule, for any record and any laddered
effect: an extension that ends within EDGE of its rung's bound is identified
again, as it was (the complex over all its parameters, then the refinement),
on the rung beyond that edge, from its point, and walks on while it keeps
ending on the edge and fitting better, at most STEPS rungs. This is
estimation of a candidate that has passed its tests; it adds no hypothesis
to them."""
from __future__ import annotations

import dataclasses
import logging
import math
from typing import Callable

import numpy as np

from .catalogue import CATALOGUE
from ..objective.problem import weighted_residual

log = logging.getLogger(__name__)

EDGE = 0.01     # an estimate within 1 % of its rung's bound is on the edge
STEPS = 3       # rungs walked at most (a factor 1.5 ** 1.5 each: about 6 in all)


def walk_ladder(effect: str, problem, x, S: float, sim, w, fit: Callable, *, steps: int = STEPS) -> tuple:
    """(problem, x, S, sim, walked): the extended `problem` at `x` (misfit S
    in the metric w) after walking its effect's ladder; `fit(problem, x, i)`
    identifies the extension on the i-th rung walked and returns its point.
    `walked`: one entry per rung tried (empty when the effect has no ladder or
    its estimate is inside its rung)."""
    eff = CATALOGUE[effect]
    name = getattr(eff, "LADDER", None)
    walked = []
    if name is None or name not in problem.free:
        return problem, x, S, sim, walked
    k = list(problem.free).index(name)
    for i in range(steps):
        lo, hi = problem.bounds[name]
        g = float(x[k])
        edge = hi if g >= hi * (1 - EDGE) else lo if g <= lo * (1 + EDGE) else None
        if edge is None:
            break
        # the next rung centred half a rung beyond the edge, so the edge lies inside it
        rung = eff.rung(edge * math.sqrt(eff.RATIO) if edge == hi else edge / math.sqrt(eff.RATIO))
        if rung == (lo, hi) or not rung[0] < edge < rung[1]:
            break   # at the end of the ladder
        start = np.array(x, float)
        start[k] = edge
        moved = dataclasses.replace(problem, bounds={**problem.bounds, name: rung},
                                    x0={**problem.values(start)})
        try:
            xm = np.asarray(fit(moved, start, i + 1), float)
            sim_m = moved.simulate(xm)
            _, S_m = weighted_residual(moved, sim_m, w)
        except Exception as exc:   # a failed step ends the walk; what was found stands
            log.warning("%s ladder: the rung %s failed: %s", effect, rung, exc)
            walked.append({"rung": list(rung), "from": g, "error": str(exc)[:300]})
            break
        walked.append({"rung": list(rung), "from": g, "to": float(xm[k]), "S_start": float(S), "S": float(S_m)})
        if not S_m < S:
            break
        log.info("%s ladder: %s %.3g -> %.3g, S %.1f -> %.1f", effect, name, g, xm[k], S, S_m)
        problem, x, S, sim = moved, xm, float(S_m), sim_m
    return problem, x, S, sim, walked


WIDEN = 2       # the joint fit's range: this many rung ratios beyond the rung's bounds on each side


def ladder_name(effect: str, problem) -> "str | None":
    """The effect's ladder variable if it is free in `problem`, else None."""
    name = getattr(CATALOGUE[effect], "LADDER", None)
    return name if name is not None and name in problem.free else None


def widened(effect: str, problem):
    """`problem` with its ladder variable's rung widened by a whole rung on
    each side (the rungs beside it joined to it). For the joint fit of the
    base and the effect over growing windows: the rung was picked at the
    base's CoRs, and on one record of the rates benchmark (4 um drawn) the pick was the
    7.7 um rung, whose lower edge fits far worse than 4 um at the true CoRs
    (430 per sample at 5 um against 0.33); on the first 0.3 s window the gap's landscape is
    smooth enough to be searched across three rungs (2.3 to 26 um: 4.00 um,
    the noise reached)."""
    name = ladder_name(effect, problem)
    if name is None:
        return problem
    eff = CATALOGUE[effect]
    lo, hi = problem.bounds[name]
    f = eff.RATIO ** WIDEN
    return dataclasses.replace(problem, bounds={**problem.bounds, name: (lo / f, min(eff.GAP_MAX, hi * f))})


def recentred(effect: str, problem, x):
    """`problem` with its ladder variable on the rung centred on its value in
    `x` (after a fit over several rungs: what follows stays in one valley)."""
    name = ladder_name(effect, problem)
    if name is None:
        return problem
    g = float(np.asarray(x, float)[list(problem.free).index(name)])
    lo, hi = CATALOGUE[effect].rung(g)
    return dataclasses.replace(problem, bounds={**problem.bounds, name: (min(lo, g), max(hi, g))},
                               x0={**problem.values(x)})
