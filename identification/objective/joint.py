"""Several records of one sorter identified together (issue 17).

One start-up or start-stop record determines e_SW and e_RW to about ±0.04
only (docs/identification.md, "what a record can tell"); k records of the
same sorter, the chain parked elsewhere each time (`lss rig --repeat K`),
shrink that by sqrt(k). A JointProblem shares the free design variables
between its records and keeps everything else of each record its own (its
noise, its tare, and its parking position: with `trigger.s_M` free, record
k > 0 gets its own `trigger.s_M@k`). f is the sum of the records'
objectives; the residual, the simulation and the noise are the records'
side by side (7 channels per record), so the refinement and the Jacobian
intervals see every record in the objective's own metric.

It has the interface of an IdentificationProblem where `identify` needs it
(free, bounds, x0, values, simulate, samples, tare, noise, channel_errors, a
call), so `identify`, `refine` and `intervals` take it as they are.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Mapping, Optional, Sequence

import numpy as np

from lss_fmu.design import TRIGGER
from lss_fmu.variables import FORCE_CHANNELS

from .problem import IdentificationProblem


def own(k: int) -> str:
    """The name of record k's own trigger point (record 0: trigger.s_M itself)."""
    return TRIGGER if k == 0 else f"{TRIGGER}@{k}"


@dataclass
class JointProblem:
    parts: Sequence[IdentificationProblem]
    free: Optional[Sequence[str]] = None      # free variables (default: the first record's); s_M per record
    x0: Optional[dict] = None                 # start values (default: each record's own)
    name: Optional[str] = None

    def __post_init__(self):
        parts = list(self.parts)
        if not parts:
            raise ValueError("a joint problem needs at least one record")
        first = parts[0]
        for p in parts[1:]:
            for what in ("layout", "model", "objective"):
                if getattr(p, what) != getattr(first, what):
                    raise ValueError(f"{p.name}: {what} {getattr(p, what)!r} differs from {first.name}'s "
                                     f"{getattr(first, what)!r}: one sorter, one model, one objective")
            if len(p.times) != len(first.times):
                raise ValueError(f"{p.name}: {len(p.times)} samples, {first.name} {len(first.times)}: give every "
                                 f"record the same window")
        base = tuple(n for n in (first.free if self.free is None else self.free) if "@" not in n)
        given = dict(self.x0 or {})
        new = []
        for k, p in enumerate(parts):
            x0 = dict(p.x0 or {})
            x0.update({n: v for n, v in given.items() if "@" not in n and n != TRIGGER})
            if own(k) in given:
                x0[TRIGGER] = given[own(k)]
            new.append(dataclasses.replace(p, free=base, x0=x0))
        self.parts = new
        self.free = base + tuple(own(k) for k in range(1, len(new)) if TRIGGER in base)
        self.x0 = self.values(self.x0_vector()) if all(p.x0 for p in new) else None
        self.name = self.name or (first.name if len(new) == 1 else f"{first.name} (+{len(new) - 1} records)")

    def __getattr__(self, item):   # layout, model, objective, protocol, tolerance, times, rate ... of record 0
        if item == "parts" or item.startswith("__"):
            raise AttributeError(item)
        return getattr(self.parts[0], item)

    # -- the design vector -------------------------------------------------------------
    def _source(self, name: str) -> tuple:
        """(record, that record's variable) a joint variable stands for."""
        if "@" in name:
            return int(name.partition("@")[2]), TRIGGER
        return 0, name

    @property
    def dim(self) -> int:
        return len(self.free)

    @property
    def bounds(self) -> dict:
        out = dict(self.parts[0].bounds)
        for n in self.free:
            k, v = self._source(n)
            out[n] = self.parts[k].bounds[v]
        return out

    @property
    def bounds_array(self) -> list:
        b = self.bounds
        return [tuple(b[n]) for n in self.free]

    def x0_vector(self) -> Optional[np.ndarray]:
        out = []
        for n in self.free:
            k, v = self._source(n)
            p = self.parts[k]
            lo, hi = p.bounds[v]
            out.append((p.x0 or {}).get(v, 0.5 * (lo + hi)))
        return np.array(out, float)

    def part_x(self, k: int, x: Sequence[float]) -> np.ndarray:
        """Record k's design vector (its free variables) from the joint one."""
        vals = dict(zip(self.free, map(float, x)))
        return np.array([vals[own(k)] if n == TRIGGER else vals[n] for n in self.parts[k].free])

    def values(self, x: Sequence[float]) -> dict:
        out = self.parts[0].values(self.part_x(0, x))
        for k in range(1, len(self.parts)):
            out[own(k)] = self.parts[k].values(self.part_x(k, x))[TRIGGER]
        return out

    # -- evaluation ----------------------------------------------------------------------
    @property
    def samples(self) -> np.ndarray:
        return np.hstack([p.samples for p in self.parts])

    @property
    def tare(self) -> Optional[np.ndarray]:
        return None if self.parts[0].tare is None else np.concatenate([p.tare for p in self.parts])

    @property
    def noise(self) -> Optional[np.ndarray]:
        return None if self.parts[0].noise is None else np.concatenate([p.noise for p in self.parts])

    def simulate(self, x: Sequence[float], extra: Optional[Mapping[str, object]] = None) -> np.ndarray:
        return np.hstack([p.simulate(self.part_x(k, x), extra) for k, p in enumerate(self.parts)])

    def exact_indices(self) -> tuple:
        """The joint variables every record that sees them can differentiate in the core
        (IdentificationProblem.exact_indices)."""
        out = []
        for j, name in enumerate(self.free):
            v = self._source(name)[1]
            if all(self.parts[i].free.index(v) in self.parts[i].exact_indices() for i in self._holders(name)):
                out.append(j)
        return tuple(out)

    def _holders(self, name: str) -> list:
        """The records a joint variable acts on: its record for a trigger point, else all."""
        k, v = self._source(name)
        return [k] if v == TRIGGER else list(range(len(self.parts)))

    def simulate_exact(self, x: Sequence[float], ks: Sequence[int]) -> tuple:
        """(the simulation at x, {k: its derivative by x_k}): each record's own
        run with its followers; a record's columns of another record's trigger
        point are zero."""
        n = len(FORCE_CHANNELS)
        mine = [{k: p.free.index(self._source(self.free[k])[1]) for k in ks if i in self._holders(self.free[k])}
                for i, p in enumerate(self.parts)]   # per record: joint index -> the record's own free index
        tasks = [(p, self.part_x(i, x), sorted(set(mine[i].values()))) for i, p in enumerate(self.parts)]
        pool = self.pool
        if pool is None:
            runs = [_exact(t) for t in tasks]
        else:   # the records side by side: each run is a function of its record and point alone
            runs = list(pool.map(_exact, tasks))
            for (p, xi, _), (y, _) in zip(tasks, runs):
                p.remember(xi, y)
        ys, cols = [], {k: [] for k in ks}
        for i, (y, d) in enumerate(runs):
            ys.append(y)
            for k in ks:
                cols[k].append(d[mine[i][k]] if k in mine[i] else np.zeros((len(y), n)))
        return np.hstack(ys), {k: np.hstack(c) for k, c in cols.items()}

    def remember(self, x: Sequence[float], y: np.ndarray) -> None:
        """Keep `y` (the records side by side) as the simulation at x: each record its own columns."""
        n = len(FORCE_CHANNELS)
        for k, p in enumerate(self.parts):
            p.remember(self.part_x(k, x), np.asarray(y)[:, k * n:(k + 1) * n])

    @property
    def pool(self):
        return self.parts[0].pool

    @pool.setter
    def pool(self, executor) -> None:
        for p in self.parts:
            p.pool = executor

    def channel_errors(self, x: Sequence[float]) -> np.ndarray:
        """Per force channel over the records: sqrt(sum_k H_kj^2), so that
        sum_j H_j^2 is f."""
        H = np.array([p.channel_errors(self.part_x(k, x)) for k, p in enumerate(self.parts)])
        return np.sqrt(np.sum(H ** 2, axis=0))

    def __call__(self, x: Sequence[float]) -> float:
        """The sum of the records' objectives; the bad value per record if any failed."""
        fs = [p(self.part_x(k, x)) for k, p in enumerate(self.parts)]
        bad = self.parts[0].bad_value
        return float(len(fs) * bad) if any(f >= bad for f in fs) else float(sum(fs))

    def close(self) -> None:
        for p in self.parts:
            p.sim.close()


def _exact(task) -> tuple:
    """One record's simulation and its columns from the core (a pool's task)."""
    problem, x, ks = task
    return problem.simulate_exact(x, ks)
