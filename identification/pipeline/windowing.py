"""Shorter windows for records that turn chaotic: the shrink stage.

A record from rest carries the CoRs while the chain's response is a smooth
function of them. On some layouts the steering wheels start bouncing in the
guide within the first two seconds, above all once the drive brakes: from
there the forces depend on the CoRs chaotically, the objective is rough and
the roughness check (uncertainty.intervals: forward and backward differences
disagree) calls the CoRs not identifiable. The first second of the same
record is still smooth (the Cramer-Rao computation of
benchmarks/bench_information.py, benchmarks/results/information_window1.0.json).

The rule, for every record: while a CoR is rough at the optimum or a
likelihood fit stays above the declared noise (`troubles`), the next shorter
window of `LADDER` is fitted, refined from the grown trail's own point at
that length (`shrink_window`): past the onset of chaos the trail may have
been carried off, the point before it has not. Nothing of the truth is used;
the result says which windows were tried (`windows`) and its problem is the
cut one (result.json `window_s`).

A rough CoR that the next shorter window could not claim either is no
trouble (`Interval.claimable_shorter`, from this window's Jacobian): a
shorter window holds less of every variable, so shortening for it loses
information on the others and gains nothing on it. On start-stops this is
e_JR, which they do not determine at any length.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from lss_fmu.design import CORS

from .identify import local_stage, safe_nrmsd
from ..objective.joint import JointProblem

log = logging.getLogger(__name__)

LADDER = (1.5, 1.2, 1.0)   # s, tried in turn below the record's own window (layout 5: smooth from 1.0 to 1.5 s)


def truncated(problem, seconds: float):
    """The problem on the record's first `seconds` (an IdentificationProblem,
    or a joint problem cut record by record); the same FMU instance."""
    if isinstance(problem, JointProblem):
        parts = [truncated(p, seconds) for p in problem.parts]
        return JointProblem(parts, free=problem.free, x0=problem.x0, name=problem.name)
    if not (np.isfinite(seconds) and seconds > 0):
        raise ValueError(f"window {seconds!r} s: must be a positive number of seconds")
    keep = problem.times <= float(seconds) + 1e-9
    if keep.sum() < 2:
        raise ValueError(f"{problem.name}: a window of {seconds:g} s keeps fewer than two samples")
    return dataclasses.replace(problem, samples=problem.samples[keep], times=problem.times[keep])


def troubles(result, names: Sequence[str] = CORS) -> list:
    """Why the result's window is not to be trusted: the CoRs it is rough in
    that the next shorter window could claim (all of them where that was not
    asked), and 'above the noise' when a likelihood fit stays above it
    (empty: fine). Without intervals nothing is known, and nothing is
    reported."""
    if not result.intervals:
        return []
    out = [iv.name for iv in result.intervals
           if iv.name in names and not iv.smooth and iv.claimable_shorter is not False]
    if any(iv.at_noise is False for iv in result.intervals):
        out.append("above the noise")
    return out


def shrink_window(problem, res, trail, ladder, refine_evals, journal, t0):
    """`res`, or the first shorter window of `ladder` without troubles (else
    the shortest), each refined from the trail's point at the longest grown
    window not beyond it."""
    full = float(problem.times[-1])
    tried = [{"window_s": full, "f": float(res.f), "troubles": troubles(res), "seconds": float(res.seconds)}]
    steps = [s for s in sorted({float(s) for s in ladder}, reverse=True) if s < full - 1e-9]
    start_t = float(problem.times[0])
    for i, s in enumerate(steps):
        if not tried[-1]["troubles"]:
            break
        t1 = time.time()
        below = [t for t in trail if start_t + t["window_s"] <= s + 1e-9] or trail[:1]
        x_start = np.asarray(below[-1]["x"], float)
        q = truncated(problem, s)
        jr = None if journal is None else Path(journal).with_name(Path(journal).stem + f".w{s:g}.jsonl")
        f_start = float(q(x_start))
        local = local_stage(q, x_start, f_start, refine_evals, True, jr,
                            shorter=steps[i + 1] if i + 1 < len(steps) else None)
        x, f = (np.asarray(local["x"], float), float(local["f"])) if local.get("f", np.inf) < f_start \
            else (x_start, f_start)
        extra = int((local.get("refined") or {}).get("nfev", 0)) + 1
        res = dataclasses.replace(res, problem=q, x=x, f=f, H=safe_nrmsd(q, x), f0=float(q(res.x0)),
                                  H0=safe_nrmsd(q, res.x0), nfev=res.nfev + extra, evaluated=res.evaluated + extra,
                                  refined=local.get("refined"), intervals=local.get("intervals"),
                                  history_f=np.append(res.history_f, f))
        tried.append({"window_s": float(q.times[-1]), "f": f, "troubles": troubles(res),
                      "seconds": time.time() - t1, "from_window_s": float(below[-1]["window_s"])})
        log.info("%s: window %.3g s from the grown point at %.3g s, f = %.4g%s", problem.name, s,
                 below[-1]["window_s"], f, f" ({', '.join(tried[-1]['troubles'])})" if tried[-1]["troubles"] else "")
    sizes = ", ".join(f"{t['window_s']:g}" for t in tried)
    return dataclasses.replace(res, windows=tried, seconds=time.time() - t0,
                               message=res.message + (f"; windows {sizes} s" if len(tried) > 1 else ""))


__all__ = ["shrink_window", "truncated", "troubles", "LADDER"]
