"""Objective profiles: is a design variable identifiable from the record?

Along a grid of one variable, the objective with the other free variables
either held at a reference point or re-optimised (a small Complex-RF run per
grid point, warm-started from the reference). A variable is identifiable when
its profile has a clear minimum at the truth that stands out of the noise
floor: the rise over the grid is compared with the spread of the objective
under perturbations far below any useful resolution.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..optim.complex_rf import minimize_complex
from ..objective.problem import IdentificationProblem


@dataclass
class Profile:
    name: str
    grid: np.ndarray
    f: np.ndarray
    reoptimised: bool
    reference: float
    others: list = field(default_factory=list)  # re-optimised values of the other variables per point

    @property
    def argmin(self) -> float:
        return float(self.grid[int(np.nanargmin(self.f))])

    def to_dict(self) -> dict:
        return {"name": self.name, "grid": self.grid.tolist(), "f": self.f.tolist(),
                "reoptimised": self.reoptimised, "reference": self.reference, "argmin": self.argmin}


def profile(problem: IdentificationProblem, name: str, grid: Sequence[float], reference: Sequence[float],
            reoptimise_evals: int = 0, seed: int = 0) -> Profile:
    """f along `grid` for design variable `name` (one of problem.free)."""
    free = list(problem.free)
    if name not in free:
        raise ValueError(f"{name} is not a free variable of the problem ({', '.join(free)})")
    k = free.index(name)
    ref = np.asarray(reference, float)
    others = [i for i in range(len(free)) if i != k]
    f, rest = [], []
    for g in grid:
        if reoptimise_evals > 0 and others:
            def sub(y, g=g):
                x = ref.copy()
                x[others] = y
                x[k] = g
                return problem(x)
            bounds = [problem.bounds_array[i] for i in others]
            res = minimize_complex(sub, bounds, x0=ref[others], max_evals=reoptimise_evals, seed=seed)
            f.append(res.fun)
            rest.append(res.x.tolist())
        else:
            x = ref.copy()
            x[k] = g
            f.append(problem(x))
    return Profile(name, np.asarray(grid, float), np.asarray(f, float), reoptimise_evals > 0,
                   float(ref[k]), rest)


def noise_floor(problem: IdentificationProblem, reference: Sequence[float], n: int = 6,
                scale: float = 1e-3, seed: int = 0) -> np.ndarray:
    """Objective values at tiny random perturbations of the reference (each
    coordinate by `scale` of its bound range): what the objective does with no
    useful change of the parameters."""
    rng = np.random.default_rng(seed)
    ref = np.asarray(reference, float)
    span = np.array([hi - lo for lo, hi in problem.bounds_array])
    lo = np.array([b[0] for b in problem.bounds_array])
    hi = np.array([b[1] for b in problem.bounds_array])
    out = []
    for _ in range(n):
        x = np.clip(ref + scale * span * rng.uniform(-1, 1, len(ref)), lo, hi)
        out.append(problem(x))
    return np.asarray(out)
