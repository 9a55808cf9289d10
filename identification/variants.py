"""An effect whose hypotheses are discrete alternatives of one another (the
wheel's order: one, two or three lobes) is tested and extended with the one
the linear ranking put first, at the base's CoRs. Those CoRs can favour the
wrong alternative: on wheel_oor_2_a5_r03 of the rates benchmark (two lobes
drawn) one lobe was ranked first, passed every test and was confirmed, 25
times above the noise (docs/close_loop.md). So an extension that stays
above the noise is identified again with each other alternative, built from
the attribution's fit of it as the candidate was (catalogue extension, the
complex over all its parameters from the extension's base point, then the
refinement), and the one that fits best is kept. This is estimation of a
candidate that has passed its tests, whose Bonferroni m already counts every
alternative; it adds no hypothesis to them."""
from __future__ import annotations

import logging
from typing import Callable

import numpy as np

from .catalogue import CATALOGUE
from .extension import extended_problem, extension_of
from .problem import weighted_residual

log = logging.getLogger(__name__)


def best_variant(sc, att, base, ext, problem, x, S: float, sim, w, fit: Callable) -> tuple:
    """(score, ext, problem, x, S, sim, tried): the candidate `sc` (extension
    `ext`, extended `problem` at `x`, misfit S in the metric w) or the other
    alternative of its effect that fits best; `fit(problem, x, i)` identifies
    the i-th alternative's extension and returns its point. `tried`: one entry
    per alternative (empty when the effect has none)."""
    tried = []
    if not getattr(CATALOGUE[sc.effect], "VARIANTS", False):
        return sc, ext, problem, x, S, sim, tried
    values = problem.values(x)
    xb = np.array([values[n] for n in base.free])
    others = [h for h in att.all_hypotheses if h.effect == sc.effect and h.label != sc.label]
    best = (sc, ext, problem, x, S, sim)
    for i, h in enumerate(others, 1):
        try:
            ext_h = extension_of(h)
            prob = extended_problem(base, xb, ext_h)
            xh = np.asarray(fit(prob, np.array([prob.x0[n] for n in prob.free]), i), float)
            sim_h = prob.simulate(xh)
            _, S_h = weighted_residual(prob, sim_h, w)
        except Exception as exc:   # an alternative that cannot be fitted is left out, the others stand
            log.warning("%s: the alternative %s failed: %s", sc.effect, h.label, exc)
            tried.append({"hypothesis": h.label, "error": str(exc)[:300]})
            continue
        tried.append({"hypothesis": h.label, "S": float(S_h), "S_candidate": float(S)})
        if S_h < best[4]:
            best = (h, ext_h, prob, xh, float(S_h), sim_h)
    if best[0] is not sc:
        log.info("%s: %s fits better than %s (S %.1f against %.1f)", sc.effect, best[0].label, sc.label, best[4], S)
    return (*best, tried)
