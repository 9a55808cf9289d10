"""Staged identification (issue 17): the layout-dependent variables first by
Levenberg-Marquardt, then the Complex on the CoRs alone, then
Levenberg-Marquardt on everything free.

Why: on a record from rest the six layout-dependent variables (speed,
pretension, rolling resistance, trigger point, gains) set the force levels
and the speed history; they move the objective a hundred times more than the
CoRs, and smoothly. A complex with all ten free spends itself on them and
contracts with the CoRs wherever they happened to be (layout 1, start-stop:
2.4x f(truth) after about 30 CPU-minutes). A few Gauss-Newton steps put the
six near their optimum with the CoRs at their start values; the complex then
searches only the CoRs, whose landscape is the rough one, and every
evaluation reuses the relaxed chain at rest (lss_fmu.runner); the last
Levenberg-Marquardt moves all ten together to the bottom. Measured on a
start-stop of layout 1: 1.00x f(truth) in 315 simulations, 86 CPU-s.

The ordering is not always right: where the CoRs at their start values put
the six in another valley (a layout-7 record: the first stage walks the gain
K_I onto its bound), the stages end far above the noise. With the
likelihood objective that is known (the noise is declared: `at_noise`), and
`fallback_evals` then runs identify's own pipeline from the start values
(a complex over the six, then over all ten with restarts, then the
refinement), which is what reaches the noise there; the better result is
kept. Only for
an objective that is a sum of squares (problem.LINEARISABLE).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path
from typing import Optional

import numpy as np

from lss_fmu.design import LAYOUT_DEPENDENT

from .problem import LINEARISABLE, IdentificationProblem
from .uncertainty import at_noise

log = logging.getLogger(__name__)

STAGE_EVALS = 80      # simulations of the first Levenberg-Marquardt (the layout-dependent variables)
FALLBACK_RESTARTS = 2
FALLBACK_PRESOLVE = 150   # evaluations of the fallback's first complex over the six (identify(presolve=...))


def run(problem: IdentificationProblem, staged: bool = False, shrink: bool = False, grown: bool = False, **kw):
    """identify(problem, **kw), or identify_staged with the same budgets
    (`presolve`: the first stage's simulations, default STAGE_EVALS), or
    with `grown` identify_grown (`max_evals`: the complex's on the first
    window): the one door of the campaign and the command line. `shrink`:
    any of them through identification.windowing (shorter windows while a
    CoR is rough; the grown one from its own trail)."""
    from .identify import identify
    if grown:
        if staged:
            raise ValueError("choose one pipeline: staged or grown, not both")
        from .identify_grown import identify_grown
        return identify_grown(problem, shrink=shrink, **kw)
    if shrink:
        from .windowing import identify_windowed
        return identify_windowed(problem, lambda q, **k: run(q, staged, **k), **kw)
    if not staged:
        return identify(problem, **kw)
    presolve = kw.pop("presolve", 0)
    return identify_staged(problem, stage_evals=presolve or STAGE_EVALS, **kw)


def identify_staged(problem: IdentificationProblem, *, max_evals: int = 120, stage_evals: int = STAGE_EVALS,
                    refine_evals: int = 200, restarts: int = 0, seed=0, journal: Optional[Path] = None,
                    progress: bool = True, workers: int = 1, uncertainty: bool = False,
                    fallback_evals: Optional[int] = None):
    """The three stages of the module docstring; `max_evals` is the complex's
    budget over the CoRs, `stage_evals` the first and `refine_evals` the last
    Levenberg-Marquardt's. Returns an identify.IdentificationResult of the
    whole problem (`presolved`: the first stage, `refined`: the last).
    `fallback_evals` (default 4 `max_evals`; 0: none): if the stages end
    above the noise (at_noise), identify from the start values with
    FALLBACK_PRESOLVE, this budget and
    FALLBACK_RESTARTS restarts, then the same refinement; the better result
    is returned."""
    from .identify import REFINE_STEP, IdentificationResult, local_stage, safe_nrmsd, identify
    from .refine import refine
    if getattr(problem, "objective", "pointwise") not in LINEARISABLE:
        raise ValueError(f"staged identification: the {problem.objective} objective is not a sum of squares "
                         f"(use one of {', '.join(LINEARISABLE)})")
    if fallback_evals is None:
        fallback_evals = 4 * int(max_evals)
    for name, v in (("max_evals", max_evals), ("stage_evals", stage_evals), ("refine_evals", refine_evals),
                    ("restarts", restarts), ("fallback_evals", fallback_evals)):
        if int(v) < 0:
            raise ValueError(f"staged identification: {name} = {v} must be 0 or more")
    t0 = time.time()
    x0 = problem.x0_vector()
    if x0 is None:
        x0 = np.array([0.5 * (lo + hi) for lo, hi in problem.bounds_array])
    start = dict(zip(problem.free, map(float, x0)))
    # (several records together: each record's own trigger point, trigger.s_M@k, is one of them)
    six = tuple(n for n in problem.free if n.partition("@")[0] in LAYOUT_DEPENDENT)
    cors = tuple(n for n in problem.free if n not in six)
    f0 = float(problem(x0))
    pre, nfev = None, 1
    if six and stage_evals > 0:
        p6 = dataclasses.replace(problem, free=six, x0={**(problem.x0 or {}), **start})
        r6 = refine(p6, np.array([start[n] for n in six]), max_evals=int(stage_evals), rel_step=REFINE_STEP,
                    f_rtol=1e-4, central=True)
        if r6.f < f0:
            start.update(zip(six, map(float, r6.x)))
        nfev += r6.nfev
        pre = {"method": "levenberg-marquardt", "free": list(six), "f0": f0, "f": float(min(r6.f, f0)),
               "nfev": int(r6.nfev), "x": {n: start[n] for n in six}}
        log.info("%s: stage 1 (%s) f %.4g -> %.4g in %d simulations", problem.name, ", ".join(six), f0, r6.f,
                 r6.nfev)
    res = None
    if cors and max_evals > 0:
        p4 = dataclasses.replace(problem, free=cors, x0={**(problem.x0 or {}), **start})
        side = Path(journal).with_suffix(".cors.jsonl") if journal else None
        res = identify(p4, max_evals=int(max_evals), seed=seed, journal=side, progress=progress, workers=workers,
                       restarts=int(restarts))
        start.update(zip(cors, map(float, res.x)))
        nfev += res.nfev
    x = np.array([start[n] for n in problem.free])
    f = float(res.f) if res is not None else float(problem(x))
    local = local_stage(problem, x, f, int(refine_evals), uncertainty, journal)
    if local.get("f", np.inf) < f:
        x, f = np.asarray(local["x"], float), float(local["f"])
    nfev += int((local.get("refined") or {}).get("nfev", 0))
    message = "staged: " + "; ".join(
        ([f"stage 1 f {pre['f0']:.4g} -> {pre['f']:.4g}"] if pre else []) +
        ([f"complex on the CoRs: {res.message}"] if res is not None else []) +
        ([f"refined to f = {f:.4g} in {local['refined']['nfev']} simulations"] if local.get("refined") else []))
    hist = np.concatenate([[f0], np.asarray(res.history_f, float) if res is not None else [], [f]])
    out = IdentificationResult(
        problem, np.asarray(x0, float), f0, safe_nrmsd(problem, x0), x, f, safe_nrmsd(problem, x), nfev,
        nfev - (res.replayed if res is not None else 0), res.replayed if res is not None else 0, message, hist,
        time.time() - t0, iterations=res.iterations if res is not None else None,
        nfev_total=nfev + ((res.nfev_total - res.nfev) if res is not None else 0),
        nrounds=res.nrounds if res is not None else 0, workers=max(1, int(workers)),
        optimizer=res.optimizer if res is not None else None, restarts=res.restarts if res is not None else 0,
        refined=local.get("refined"), presolved=pre, intervals=local.get("intervals"))
    if fallback_evals > 0 and at_noise(problem, f) is False:
        log.info("%s: the stages end at f = %.4g, above the noise: the complex over everything", problem.name, f)
        side = Path(journal).with_suffix(".fallback.jsonl") if journal else None
        # from the start values, not the stages' point: that sits in the wrong valley, and the complex
        # (its first point the start) with a presolve of the six is what reaches the noise there
        full = identify(problem, max_evals=int(fallback_evals), seed=seed, journal=side, progress=progress,
                        workers=workers, restarts=FALLBACK_RESTARTS, refine_evals=int(refine_evals),
                        uncertainty=uncertainty, presolve=FALLBACK_PRESOLVE)
        used = out.nfev + full.nfev
        if full.f < f:
            out = dataclasses.replace(full, x0=out.x0, f0=f0, H0=out.H0, nfev=used, presolved=pre,
                                      evaluated=out.evaluated + full.evaluated, seconds=time.time() - t0,
                                      message=f"{message}; above the noise: {full.message}")
        else:
            out = dataclasses.replace(out, nfev=used, evaluated=out.evaluated + full.evaluated,
                                      seconds=time.time() - t0,
                                      message=f"{message}; the complex over everything did no better")
    return out
