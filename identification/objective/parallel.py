"""Independent simulations of one identification side by side.

A problem given a pool (`pooled`: a concurrent.futures Executor, a local
process pool or a Dask client's executor) runs the simulations of one round
(a Jacobian's columns) on its workers; without one they run here, one after
the other, in the same order. A simulation is a pure function of its point
(problem.simulate), so either way each point gets the same array, bit for
bit, and everything computed from them is the serial run's.

A worker's copy of the problem has nothing kept (problem.simulate's memo);
the round's known point (the Jacobian's base) is sent along and kept there
first, so that a joint problem's column of one record's trigger point runs
that record alone on a worker too. What comes back is kept here.
"""
from __future__ import annotations

import contextlib
import logging
from concurrent.futures import Executor, ProcessPoolExecutor
from typing import Iterator, Optional, Sequence

import numpy as np

log = logging.getLogger(__name__)


class Failed:
    """A simulation that raised, as a worker hands it back (the exception's words)."""

    def __init__(self, message: str):
        self.message = message

    def __repr__(self) -> str:
        return f"Failed({self.message!r})"


def simulate_all(problem, xs: Sequence[np.ndarray], base: Optional[tuple] = None) -> list:
    """The simulation at each of `xs` (a Failed in place of one that raised),
    on the problem's pool when it has one and there is more than one point,
    else here in order. `base`: (x, simulation) already known, kept by the
    workers before they run."""
    pool = getattr(problem, "pool", None)
    if pool is None or len(xs) < 2:
        return [_simulate(problem, x) for x in xs]
    out = list(pool.map(_task, [(problem, np.asarray(x, float), base) for x in xs]))
    for x, y in zip(xs, out):
        if not isinstance(y, Failed):
            problem.remember(x, y)
    return out


def _simulate(problem, x) -> object:
    try:
        return problem.simulate(x)
    except Exception as exc:   # the caller decides what a failed point means
        return Failed(f"{type(exc).__name__}: {exc}")


def _task(args) -> object:
    problem, x, base = args
    if base is not None:
        problem.remember(*base)
    return _simulate(problem, x)


@contextlib.contextmanager
def pooled(problem, workers: int = 1, executor: Optional[Executor] = None) -> Iterator:
    """The problem with a pool for the time of the block: `executor` if given
    (a Dask client's get_executor(), say), else `workers` local processes
    (1: none, the serial run)."""
    if executor is None and int(workers) <= 1:
        yield problem
        return
    own = executor is None
    ex = ProcessPoolExecutor(int(workers)) if own else executor
    before = problem.pool
    problem.pool = ex
    try:
        yield problem
    finally:
        problem.pool = before
        if own:
            ex.shutdown(wait=True, cancel_futures=True)


__all__ = ["simulate_all", "pooled", "Failed"]
