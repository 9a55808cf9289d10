"""The extended identification: the winning effect switched on, its
parameters added to the design vector, identified again from the previous
optimum. The base variables keep their full bounds: a missing
effect can drag the base optimum far (onto a bound), and the extended model
must be free to walk back."""
from __future__ import annotations

import dataclasses
import numpy as np

from .attribution import HypothesisScore
from .catalogue import CATALOGUE, SENSOR_CH, Extension, SensorError
from ..objective.problem import IdentificationProblem
from lss_fmu.variables import BY_NAME


def extension_of(score: HypothesisScore) -> Extension:
    effect = CATALOGUE[score.effect]
    if isinstance(effect, SensorError):
        return effect.extension(score.hypothesis, score.coef, effect.select(score.coef, score.probe_gain))
    return effect.extension(score.hypothesis, score.coef)


def extended_problem(problem: IdentificationProblem, x: np.ndarray, ext: Extension) -> IdentificationProblem:
    """The problem with the effect's parameters free, started at x (base) and
    the fitted effect values."""
    bounds = dict(problem.bounds)   # the base variables keep their full bounds (module docstring)
    values = problem.values(x)
    x0 = dict(values)
    for name, (lo, hi) in ext.free.items():
        lo, hi = _within_fmu_range(name, lo, hi)
        bounds[name] = (lo, hi)
        x0[name] = float(np.clip(ext.x0[name], lo, hi))
    fixed = {**problem.fixed, **ext.fixed}
    tare = _tare_without_free_offsets(problem, x, ext, x0)
    return dataclasses.replace(problem, bounds=bounds, fixed=fixed, free=tuple(problem.free) + tuple(ext.free),
                               x0=x0, tare=tare)


def _within_fmu_range(name: str, lo: float, hi: float) -> tuple:
    """The bounds cut to the FMU variable's declared range: a design point
    outside it is refused by the FMU (a failed simulation, not a bad fit)."""
    var = BY_NAME.get(name)
    if var is not None:
        if var.min is not None:
            lo = max(lo, float(var.min))
        if var.max is not None:
            hi = min(hi, float(var.max))
    if not lo < hi:
        raise ValueError(f"{name}: no room within the FMU's range for the bounds [{lo}, {hi}]")
    return lo, hi


def _tare_without_free_offsets(problem: IdentificationProblem, x: np.ndarray, ext: Extension, x0: dict):
    """A channel whose offset the extension identifies loses its tare: the
    offset parameter now explains the whole zero error, in-specification part
    included (else the identified offset would fall short by what the tare
    took). Its start value gets that part back (x0 is updated in place)."""
    if problem.tare is None:
        return None
    freed = [j for j, ch in enumerate(SENSOR_CH) if f"effects.sensor.offset.{ch}" in ext.free]
    if not freed:
        return problem.tare
    mean_r = (problem.samples - problem.simulate(x)).mean(axis=0)
    taken = np.clip(mean_r, -problem.tare, problem.tare)
    tare = np.array(problem.tare, float)
    for j in freed:
        name = f"effects.sensor.offset.{SENSOR_CH[j]}"
        lo, hi = ext.free[name]
        x0[name] = float(np.clip(x0[name] + taken[j], lo, hi))
        tare[j] = 0.0
    return tare
