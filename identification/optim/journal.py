"""The journal of an identification: every evaluation on disk as it is known.

One JSON line per evaluation (x and f), flushed: a run interrupted at any
moment and started again with the same seed asks for the same points, and the
journal answers them without simulating (identification.pipeline.identify).

A journal answers for the objective that wrote it only. Replayed into an
objective that has changed since (another record under the same name, a
window, a filter rate, the FMU or the code that makes f), its values would
steer the optimiser through a landscape that is not there, silently. So
before it answers, `vouch` evaluates its best point again: if f is not what
the journal holds (within VOUCH_RTOL) the journal is set aside, renamed with
`.stale`, with its refinement (`.local.json`), and the run starts afresh, with
a logged warning. One evaluation per resume is the price.
"""
from __future__ import annotations

import json
import logging
import math
import os
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

log = logging.getLogger(__name__)

VOUCH_RTOL = 1e-6   # a journaled f evaluated again agrees this closely (the simulation is deterministic)


def point_key(x) -> str:
    return np.asarray(x, float).tobytes().hex()


def point_of(key: str) -> np.ndarray:
    """The point a point_key was made from (the start of a stored refinement: JOURNAL.local.json)."""
    return np.frombuffer(bytes.fromhex(key), dtype=float).copy()


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
        f = self.cache.get(point_key(x))
        if f is not None:
            self.replayed += 1
        return f

    def put(self, x, f: float) -> None:
        k = point_key(x)
        self.cache[k] = f
        if self._fh:
            self._fh.write(json.dumps({"k": k, "x": list(map(float, x)), "f": f}) + "\n")
            self._fh.flush()
            os.fsync(self._fh.fileno())

    def close(self) -> None:
        if self._fh:
            self._fh.close()
            self._fh = None

    def vouch(self, objective: Callable, dim: int, bad: Optional[float] = None) -> bool:
        """True if the journal answers for `objective` (a dim-variable
        function): its best finite point, evaluated again, gives the f it
        holds. Otherwise the journal is set aside (`.stale`) and starts empty.
        An empty journal vouches for anything; one without a finite value
        below `bad` (every point failed) cannot be checked and is kept."""
        points = [(f, k) for k, f in self.cache.items() if math.isfinite(f) and (bad is None or f < bad)]
        if not points:
            return True
        f_old, k = min(points)
        x = point_of(k)
        try:
            f_new = float(objective(x)) if x.size == dim else math.nan
        except Exception as exc:   # a point the objective no longer takes: not its journal
            log.debug("journal %s: its best point raised %s", self.path, exc)
            f_new = math.nan
        if abs(f_new - f_old) <= VOUCH_RTOL * max(1.0, abs(f_old)):
            return True
        n_points = len(self.cache)
        where = self._set_aside()
        log.warning("journal %s: its best point gives f = %.6g now, it holds %.6g (%d points, %d variables for "
                    "%d): another record, setting, FMU or code wrote it; set aside as %s, the run starts afresh",
                    self.path, f_new, f_old, n_points, x.size, dim, where)
        return False

    def _set_aside(self) -> Optional[Path]:
        """Rename the journal (and its refinement, .local.json) with `.stale`,
        numbered if that name is taken, and start an empty one: nothing lost."""
        self.close()
        self.cache.clear()
        self.replayed = 0
        if self.path is None:
            return None
        n, where = 0, None
        while where is None or where.exists():
            n += 1
            where = self.path.with_name(f"{self.path.stem}.stale{'' if n == 1 else n}{self.path.suffix}")
        if self.path.exists():
            self.path.rename(where)
        local = self.path.with_suffix(".local.json")
        if local.exists():
            local.rename(where.with_suffix(".local.json"))
        self._fh = open(self.path, "a")
        return where


class JournaledObjective:
    """The problem's objective behind the journal (picklable for workers)."""

    def __init__(self, problem, journal: Journal):
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
