"""One identification: a problem, Complex-RF, a journal, a result file.

Every evaluation is appended to a journal (one JSON line, flushed) as soon as
it is known. Run again after an interruption, the same seed makes the
optimiser ask for the same points in the same order, and the journal answers
them without simulating: the result is the same and no evaluation is lost or
counted twice. The result is written atomically.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from .complex_rf import minimize_complex
from .problem import SHORT, IdentificationProblem, nrmsd


def _key(x) -> str:
    return np.asarray(x, float).tobytes().hex()


class Journal:
    """Evaluations on disk: x -> f, appended line by line."""

    def __init__(self, path: Optional[Path]):
        self.path = Path(path) if path else None
        self.cache: dict[str, float] = {}
        self.replayed = 0
        if self.path and self.path.exists():
            with open(self.path) as fh:
                for line in fh:
                    try:
                        rec = json.loads(line)
                    except json.JSONDecodeError:
                        break  # a line cut by the interruption: everything after it is redone
                    self.cache[rec["k"]] = float(rec["f"])
        self._fh = open(self.path, "a") if self.path else None

    def get(self, x) -> Optional[float]:
        f = self.cache.get(_key(x))
        if f is not None:
            self.replayed += 1
        return f

    def put(self, x, f: float) -> None:
        k = _key(x)
        self.cache[k] = f
        if self._fh:
            self._fh.write(json.dumps({"k": k, "x": list(map(float, x)), "f": f}) + "\n")
            self._fh.flush()
            os.fsync(self._fh.fileno())

    def close(self) -> None:
        if self._fh:
            self._fh.close()
            self._fh = None


class JournaledObjective:
    """The problem's objective behind the journal (picklable for workers)."""

    def __init__(self, problem: IdentificationProblem, journal: Journal):
        self.problem, self.journal = problem, journal
        self.evaluated = 0

    def __call__(self, x) -> float:
        f = self.journal.get(x)
        if f is None:
            f = self.problem(x)
            self.evaluated += 1
            self.journal.put(x, f)
        return f



def journaled_map(problem: IdentificationProblem, journal: Journal, executor) -> Callable:
    """A map for the parallel optimiser: the journal answers what it knows,
    the executor's workers (one FMU instance each) simulate the rest."""
    counter = {"evaluated": 0}

    def _map(fn, xs: Sequence) -> list:
        out = [journal.get(x) for x in xs]
        todo = [i for i, f in enumerate(out) if f is None]
        if todo:
            for i, f in zip(todo, executor.map(problem, [xs[i] for i in todo])):
                out[i] = float(f)
                journal.put(xs[i], out[i])
            counter["evaluated"] += len(todo)
        return out
    _map.counter = counter
    return _map


@dataclass
class IdentificationResult:
    problem: IdentificationProblem
    x0: np.ndarray
    f0: float
    H0: np.ndarray
    x: np.ndarray
    f: float
    H: np.ndarray
    nfev: int
    evaluated: int
    replayed: int
    message: str
    history_f: np.ndarray
    seconds: float

    def to_dict(self) -> dict:
        p = self.problem
        return {
            "measurement": p.name, "model": p.model, "layout": p.layout,
            "free": list(p.free), "bounds": {k: list(p.bounds[k]) for k in p.free},
            "x0": dict(zip(p.free, map(float, self.x0))), "f0": self.f0,
            "nrmsd0": dict(zip(_channels(), map(float, self.H0))),
            "x": dict(zip(p.free, map(float, self.x))), "f": self.f,
            "nrmsd": dict(zip(_channels(), map(float, self.H))),
            "values": {SHORT[k]: v for k, v in p.values(self.x).items()},
            "nfev": self.nfev, "simulated": self.evaluated, "replayed": self.replayed,
            "message": self.message, "history_f": list(map(float, self.history_f)),
            "seconds": self.seconds, "window_s": float(p.times[-1]),
        }


def _channels() -> list:
    from lss_fmu.variables import FORCE_CHANNELS
    return FORCE_CHANNELS


def identify(problem: IdentificationProblem, *, max_evals: int = 5000, seed=0,
             journal: Optional[Path] = None, progress: bool = True, f_tol: float = 1e-6,
             x_tol: float = 1e-4, workers: int = 1) -> IdentificationResult:
    """Complex-RF on the problem (the parallel variant with `workers` > 1,
    each worker process with its own FMU instance)."""
    t0 = time.time()
    jr = Journal(journal)
    obj = JournaledObjective(problem, jr)
    x0 = problem.x0_vector()
    if x0 is None:
        x0 = np.array([0.5 * (lo + hi) for lo, hi in problem.bounds_array])
    opts = dict(x0=x0, max_evals=max_evals, seed=seed, progress=progress, f_tol=f_tol, x_tol=x_tol)
    try:
        f0 = obj(x0)
        if workers > 1:
            from concurrent.futures import ProcessPoolExecutor
            from .complex_rfp import minimize_complex_parallel
            with ProcessPoolExecutor(workers) as ex:
                mapper = journaled_map(problem, jr, ex)
                res = minimize_complex_parallel(problem, problem.bounds_array, n_parallel=workers,
                                                map_fn=mapper, **opts)
            evaluated = obj.evaluated + mapper.counter["evaluated"]
        else:
            res = minimize_complex(obj, problem.bounds_array, **opts)
            evaluated = obj.evaluated
        H0 = _safe_H(problem, x0)
        H = _safe_H(problem, res.x)
    finally:
        jr.close()
    return IdentificationResult(problem, x0, f0, H0, np.asarray(res.x), float(res.fun), H, res.nfev,
                                evaluated, jr.replayed, res.message, np.asarray(res.history.f, float),
                                time.time() - t0)


def _safe_H(problem: IdentificationProblem, x) -> np.ndarray:
    try:
        return problem.channel_errors(x)
    except Exception:
        return np.full(len(_channels()), np.nan)
