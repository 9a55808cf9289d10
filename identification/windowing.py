"""Shorter windows for records that turn chaotic (issue 17).

A record from rest carries the CoRs while the chain's response is a smooth
function of them. On some layouts (layout 5 of the recovery set) the
steering wheels start bouncing in the guide within the first two seconds,
above all once the drive brakes: from there the forces depend on the CoRs
chaotically, the objective is rough, the complex stops in a wrong basin and
the roughness check (uncertainty.intervals: forward and backward differences
disagree) calls the CoRs not identifiable. The first second of the same
record is still smooth (the Cramer-Rao computation of
benchmarks/bench_information.py: all six of layout 5's start-stops at 1.0 s,
benchmarks/results/information_window1.0.json).

`identify_windowed` identifies at the record's window first; when a CoR is
rough at the optimum, or a likelihood fit stays above the declared noise, it
cuts the record to the next window of `ladder` and identifies again from the
optimum it has, until every CoR is smooth and the fit at the noise. Nothing
of the truth is used: the test is the one the intervals report anyway. The
result says which windows were tried (`windows`) and its problem is the cut
one (result.json `window_s`).
"""
from __future__ import annotations

import dataclasses
import logging
from typing import Callable, Sequence

import numpy as np

from lss_fmu.design import CORS

log = logging.getLogger(__name__)

LADDER = (1.5, 1.2, 1.0)   # s, tried in turn below the record's own window (layout 5: smooth from 1.0 to 1.5 s)


def truncated(problem, seconds: float):
    """The problem on the record's first `seconds` (an IdentificationProblem,
    or a joint problem cut record by record); the same FMU instance."""
    from .joint import JointProblem
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
    """Why the result's window is not to be trusted: the CoRs it is rough in,
    and 'above the noise' when a likelihood fit stays above it (empty: fine).
    Without intervals nothing is known, and nothing is reported."""
    if not result.intervals:
        return []
    out = [iv.name for iv in result.intervals if iv.name in names and not iv.smooth]
    if any(iv.at_noise is False for iv in result.intervals):
        out.append("above the noise")
    return out


def identify_windowed(problem, run: Callable, ladder: Sequence[float] = LADDER, **kw):
    """run(problem, **kw) (identify, or staged.run with its flag bound), then
    on ever shorter windows of `ladder` (only those below the record's own)
    while `troubles` reports any; each later run starts from the optimum of
    the one before. Returns the first result without troubles, else the
    shortest window's; `windows` lists every window tried with its f and
    troubles. Needs `uncertainty=True` (the roughness check)."""
    if not kw.get("uncertainty"):
        raise ValueError("identify_windowed needs uncertainty=True: the roughness of the CoRs decides the window")
    full = float(problem.times[-1])
    steps = [w for w in sorted(set(float(w) for w in ladder), reverse=True) if w < full - 1e-9]
    journal = kw.pop("journal", None)
    tried, current, res = [], problem, None
    for w in [None] + steps:
        if w is not None:
            current = _starting(truncated(problem, w), res.problem.values(res.x))
        jr = None if journal is None else (journal if w is None else _suffix(journal, f".w{w:g}"))
        res = run(current, journal=jr, **kw)
        why = troubles(res)
        tried.append({"window_s": float(current.times[-1]), "f": float(res.f), "troubles": why,
                      "seconds": float(res.seconds)})
        log.info("%s: window %.3g s, f = %.4g%s", problem.name, current.times[-1], res.f,
                 f" ({', '.join(why)})" if why else "")
        if not why:
            break
    sizes = ", ".join(f"{t['window_s']:g}" for t in tried)
    return dataclasses.replace(res, windows=tried,
                               message=res.message + (f"; windows {sizes} s" if len(tried) > 1 else ""))


def _starting(problem, values: dict):
    """The problem started at `values` (design name -> value; a joint problem's
    trigger.s_M@k too)."""
    from .joint import JointProblem
    if isinstance(problem, JointProblem):
        return JointProblem(problem.parts, free=problem.free, x0=values, name=problem.name)
    return dataclasses.replace(problem, x0={**(problem.x0 or {}), **values})


def _suffix(path, tag: str):
    from pathlib import Path
    p = Path(path)
    return p.with_name(p.stem + tag + p.suffix)


__all__ = ["identify_windowed", "truncated", "troubles", "LADDER"]
