"""One identification: a problem, Complex-RF, a journal, a result file.

Every evaluation is appended to a journal (one JSON line, flushed) as soon as
it is known. Run again after an interruption, the same seed makes the
optimiser ask for the same points in the same order, and the journal answers
them without simulating: the result is the same and no evaluation is lost or
counted twice. The result is written atomically.

With `workers` > 1 the parallel Complex-RFP (speculative strategy) asks for
exactly the points the serial method would use, plus speculative ones it may
discard; the journal holds all of them. The result's history is the
optimiser's own: the evaluations it used, in the order it used them
(`ComplexHistory.used_order`), and its iteration table, so a run with workers
and a serial run from the same seed give the same history, figure and JSON.
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
from .optim_result import ComplexResult, _jsonable
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
            good = 0  # bytes of whole, readable lines
            with open(self.path, "rb") as fh:
                for line in fh:
                    try:
                        if not line.endswith(b"\n"):
                            raise ValueError("line without its end")
                        rec = json.loads(line)
                        k, f = rec["k"], float(rec["f"])
                    except (ValueError, KeyError, TypeError):
                        break  # a line cut by the interruption: everything after it is redone
                    self.cache[k] = f
                    good += len(line)
            if good < self.path.stat().st_size:
                # drop the cut line, or the next record would be glued onto it and
                # lost, with everything after it, at the next restart
                with open(self.path, "r+b") as fh:
                    fh.truncate(good)
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
            self.evaluated += 1
            f = self.problem(x)  # an exception is not journaled: the optimiser makes it a bad point
            self.journal.put(x, f)
        return f


def journaled_map(journal: Journal, executor) -> Callable:
    """A `map_fn` for the parallel optimiser: the journal answers what it
    knows; the executor's workers (one FMU instance each) apply `fn`, the
    optimiser's wrapped objective (`SafeObjective`), to the rest. An exception
    in a worker thus comes back as a bad point with its message, which the
    optimiser logs and ranks worst; the run goes on. Values are journaled as
    they come back; an evaluation that raised is not journaled (as in the
    serial case) and is tried again after a restart."""
    counter = {"evaluated": 0}

    def _map(fn: Callable, xs: Sequence) -> list:
        out: list = [journal.get(x) for x in xs]
        todo = [i for i, f in enumerate(out) if f is None]
        if todo:
            counter["evaluated"] += len(todo)
            for i, r in zip(todo, executor.map(fn, [xs[i] for i in todo])):
                out[i] = r
                f, err = (r[0], r[2]) if isinstance(r, tuple) and len(r) == 3 else (r, None)
                if err is None:  # a value (possibly non-finite) the objective returned
                    journal.put(xs[i], float(f))
        return out  # journal answers as plain values, the rest as (f, bad, error)
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
    history_f: np.ndarray            # f of the used evaluations, in the order the method used them
    seconds: float
    iterations: dict = None          # the optimiser's iteration table (ComplexHistory.iterations)
    nfev_total: int = 0              # all evaluations, incl. speculative ones the method discarded
    nrounds: int = 0                 # wall-clock rounds (batches of evaluations)
    workers: int = 1
    optimizer: Optional[ComplexResult] = None  # the optimiser's result, with its full history

    def to_dict(self) -> dict:
        p = self.problem
        return {
            "measurement": p.name, "model": p.model, "layout": p.layout,
            "free": list(p.free), "bounds": {k: list(p.bounds[k]) for k in p.free},
            "x0": dict(zip(p.free, map(float, self.x0))), "f0": self.f0,
            "nrmsd0": dict(zip(_channels(), map(float, self.H0))),
            "x": dict(zip(p.free, map(float, self.x))), "f": self.f,
            "nrmsd": dict(zip(_channels(), map(float, self.H))),
            "values": {SHORT.get(k, k): v for k, v in p.values(self.x).items()},
            "nfev": self.nfev, "simulated": self.evaluated, "replayed": self.replayed,
            "message": self.message, "history_f": list(map(float, self.history_f)),
            "iterations": _jsonable(self.iterations or {}),
            "nfev_total": self.nfev_total, "discarded": self.nfev_total - self.nfev,
            "rounds": self.nrounds, "workers": self.workers,
            "seconds": self.seconds, "window_s": float(p.times[-1]),
        }


def _channels() -> list:
    from lss_fmu.variables import FORCE_CHANNELS
    return FORCE_CHANNELS


def identify(problem: IdentificationProblem, *, max_evals: int = 5000, seed=0,
             journal: Optional[Path] = None, progress: bool = True, f_tol: float = 1e-6,
             x_tol: float = 1e-4, workers: int = 1) -> IdentificationResult:
    """Complex-RF on the problem (the parallel variant with `workers` > 1,
    each worker process with its own FMU instance).

    `nfev` and `history_f` count the evaluations the method used (`max_evals`
    limits them); with workers, `nfev_total` adds the speculative ones it
    discarded. An exception of the objective, in this process or a worker, is
    a bad point with a logged line, never the end of the run."""
    t0 = time.time()
    jr = Journal(journal)
    x0 = problem.x0_vector()
    if x0 is None:
        x0 = np.array([0.5 * (lo + hi) for lo, hi in problem.bounds_array])
    opts = dict(x0=x0, max_evals=max_evals, seed=seed, progress=progress, f_tol=f_tol, x_tol=x_tol)
    try:
        if workers > 1:
            from concurrent.futures import ProcessPoolExecutor
            from .complex_rfp import minimize_complex_parallel
            with ProcessPoolExecutor(workers) as ex:
                mapper = journaled_map(jr, ex)
                res = minimize_complex_parallel(problem, problem.bounds_array, n_parallel=workers,
                                                strategy="speculative", map_fn=mapper, **opts)
            evaluated = mapper.counter["evaluated"]
        else:
            obj = JournaledObjective(problem, jr)
            res = minimize_complex(obj, problem.bounds_array, **opts)
            evaluated = obj.evaluated
        hist = res.history
        used = hist.used_order()
        history_f = np.asarray(hist.f, float)[used]
        f0 = float(history_f[0])  # x0 is the first point of the initial complex
        H0 = _safe_H(problem, x0)
        H = _safe_H(problem, res.x)
    finally:
        jr.close()
    return IdentificationResult(problem, x0, f0, H0, np.asarray(res.x), float(res.fun), H, int(res.nfev_used),
                                evaluated, jr.replayed, res.message, history_f, time.time() - t0,
                                iterations={k: np.asarray(v).copy() for k, v in hist.iterations.items()},
                                nfev_total=int(res.nfev), nrounds=int(res.nrounds), workers=max(1, int(workers)),
                                optimizer=res)


def _safe_H(problem: IdentificationProblem, x) -> np.ndarray:
    try:
        return problem.channel_errors(x)
    except Exception:
        return np.full(len(_channels()), np.nan)
