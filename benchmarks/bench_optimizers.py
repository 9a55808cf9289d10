#!/usr/bin/env python3
"""Side-by-side benchmark of the derivative-free optimisers on one budget.

Methods: Complex-RF (serial reference), Complex-RFP (speculative and
multi-direction strategies, ``--n-parallel`` evaluations per round),
scipy's differential evolution and CMA-ES (``cma``).  Each method runs from
``--seeds`` seeds with the same evaluation budget; every evaluation is
recorded, and from those traces the script reports, per problem and method:

* ``reach``   share of runs whose best value reached the target ``f <= f_target``
* ``evals``   evaluations to reach the target: median and IQR over the runs that reached it
* ``rounds``  the same in wall-clock rounds with ``n_parallel`` workers: a round is
              one batch of evaluations that can run at once (serial Complex-RF: one
              evaluation; Complex-RFP: its batches; DE and CMA-ES: a generation of
              ``NP`` or ``lambda`` points takes ``ceil(NP / n_parallel)`` rounds)
* ``found``   share of runs whose final point is within 1 % of the bound range of the
              known optimum in every coordinate (the criterion of tests/test_complex_rf.py)
* ``stop``    evaluations until the method stopped on its own criteria (median)
* ``f_final`` median final best value

Usage::

    .venv/bin/python benchmarks/bench_optimizers.py                 # test functions, writes docs/optimizer_benchmark.md
    .venv/bin/python benchmarks/bench_optimizers.py --seeds 5 --no-write

From Python, on any objective (e.g. the identification problem)::

    from benchmarks.bench_optimizers import compare, format_table
    stats = compare(fun, bounds, budget=5000, seeds=range(10), f_target=None, n_jobs=4)
    print(format_table({"identification": stats}))

``f_target=None`` takes the best value found by any run plus 1 % (a relative
target) because the true optimum is unknown; ``n_jobs > 1`` runs the (method,
seed) runs in worker processes (``fun`` must then be picklable).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from identification.optim.complex_rf import minimize_complex, parse_bounds  # noqa: E402
from identification.optim.complex_rfp import minimize_complex_parallel  # noqa: E402

METHODS = ("complex-rf", "complex-rfp", "complex-rfp-md", "de", "cma-es")


# --------------------------------------------------------------------------
# test functions
# --------------------------------------------------------------------------

SPHERE_SHIFT = np.array([0.5, -1.2, 0.8, 1.7, -0.3, 2.1, -2.4, 1.1, 0.2, -0.9])


def shifted_sphere(x: np.ndarray) -> float:
    return float(np.sum((x - SPHERE_SHIFT[: x.size]) ** 2))


def rosenbrock(x: np.ndarray) -> float:
    return float(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2))


def rastrigin(x: np.ndarray) -> float:
    return float(10.0 * x.size + np.sum(x**2 - 10.0 * np.cos(2.0 * np.pi * x)))


@dataclass
class Problem:
    name: str
    fun: Callable[[np.ndarray], float]
    bounds: list[tuple[float, float]]
    x_opt: np.ndarray | None
    f_target: float | None


def test_problems() -> list[Problem]:
    return [
        Problem("sphere-2", shifted_sphere, [(-5.0, 5.0)] * 2, SPHERE_SHIFT[:2], 1e-4),
        Problem("sphere-5", shifted_sphere, [(-5.0, 5.0)] * 5, SPHERE_SHIFT[:5], 1e-4),
        Problem("rosenbrock-2", rosenbrock, [(-2.048, 2.048)] * 2, np.ones(2), 1e-4),
        Problem("rosenbrock-4", rosenbrock, [(-2.048, 2.048)] * 4, np.ones(4), 1e-4),
        Problem("rastrigin-2", rastrigin, [(-5.12, 5.12)] * 2, np.zeros(2), 1e-4),
        Problem("rastrigin-3", rastrigin, [(-5.12, 5.12)] * 3, np.zeros(3), 1e-4),
    ]


# --------------------------------------------------------------------------
# one run of one method
# --------------------------------------------------------------------------


class _Trace:
    """Objective wrapper recording every value (non-finite and errors -> inf)."""

    def __init__(self, fun: Callable[[np.ndarray], float], lo: np.ndarray | None = None,
                 hi: np.ndarray | None = None):
        self.fun, self.lo, self.hi = fun, lo, hi
        self.f: list[float] = []

    def __call__(self, x: np.ndarray) -> float:
        x = np.asarray(x, dtype=float)
        if self.lo is not None:  # CMA-ES works on [0, 1]^m
            x = self.lo + np.clip(x, 0.0, 1.0) * (self.hi - self.lo)
        try:
            v = float(self.fun(x))
        except Exception:  # noqa: BLE001
            v = math.inf
        if not math.isfinite(v):
            v = math.inf
        self.f.append(v)
        return v if math.isfinite(v) else 1e300


@dataclass
class Run:
    method: str
    seed: int
    f_trace: np.ndarray  # value of every evaluation, in evaluation order
    rounds_of_eval: np.ndarray  # wall-clock round (1-based, cumulative) after each evaluation
    x_best: np.ndarray
    f_best: float
    nfev: int
    seconds: float
    info: dict[str, Any] = field(default_factory=dict)


def _generation_rounds(n: int, pop: int, first: int, n_parallel: int) -> np.ndarray:
    """Rounds after each of ``n`` evaluations for a generational method."""
    idx = np.arange(n)
    per_gen = math.ceil(pop / n_parallel)
    first_rounds = math.ceil(first / n_parallel)
    gen = np.where(idx < first, -1, (idx - first) // pop)
    return np.where(gen < 0, first_rounds, first_rounds + (gen + 1) * per_gen)


def run_method(method: str, fun: Callable, bounds: Any, budget: int, seed: int,
               n_parallel: int = 4) -> Run:
    lo, hi = parse_bounds(bounds)
    m = lo.size
    t0 = time.perf_counter()
    if method in ("complex-rf", "complex-rfp", "complex-rfp-md"):
        tr = _Trace(fun)
        if method == "complex-rf":
            res = minimize_complex(tr, bounds, max_evals=budget, seed=seed)
        else:
            strategy = "speculative" if method == "complex-rfp" else "multidirection"
            res = minimize_complex_parallel(tr, bounds, max_evals=budget, seed=seed,
                                            n_parallel=n_parallel, strategy=strategy)
        h = res.history
        rounds = h.round.astype(int) + 1
        # speculative runs evaluate points the method never uses: a target reached
        # there does not count, but the evaluations (cost) do
        f_used = np.where(h.discarded, np.inf, h.f)
        return Run(method, seed, f_used, rounds, res.x, res.fun, res.nfev,
                   time.perf_counter() - t0, {"message": res.message, "nrounds": res.nrounds})
    if method == "de":
        from scipy.optimize import differential_evolution

        tr = _Trace(fun)
        popsize = 15
        NP = popsize * m
        maxiter = max(1, budget // NP - 1)
        res = differential_evolution(tr, list(zip(lo, hi)), popsize=popsize, maxiter=maxiter,
                                     seed=seed, polish=False, updating="deferred")
        f = np.asarray(tr.f[:budget])
        return Run(method, seed, f, _generation_rounds(f.size, NP, NP, n_parallel), np.asarray(res.x),
                   float(res.fun), len(tr.f), time.perf_counter() - t0, {"message": str(res.message)})
    if method == "cma-es":
        import cma

        tr = _Trace(fun, lo, hi)
        rng = np.random.default_rng(seed)
        x0 = rng.random(m)
        opts = {"bounds": [0.0, 1.0], "maxfevals": budget, "seed": int(seed) + 1, "verbose": -9}
        es = cma.CMAEvolutionStrategy(x0, 0.3, opts)
        es.optimize(tr)
        lam = es.popsize
        xb = es.result.xbest
        x_best = lo + np.clip(np.asarray(xb), 0, 1) * (hi - lo) if xb is not None else lo
        f = np.asarray(tr.f[:budget])
        return Run(method, seed, f, _generation_rounds(f.size, lam, lam, n_parallel), x_best,
                   float(np.min(f)) if f.size else math.inf, len(tr.f), time.perf_counter() - t0,
                   {"message": str(es.stop())})
    raise ValueError(f"unknown method {method!r}; choose from {METHODS}")


def _run_job(job: tuple) -> Run:
    return run_method(*job)


# --------------------------------------------------------------------------
# statistics
# --------------------------------------------------------------------------


def _med_iqr(values: Sequence[float]) -> tuple[float, float, float]:
    if len(values) == 0:
        return (math.nan, math.nan, math.nan)
    q1, med, q3 = np.percentile(np.asarray(values, dtype=float), [25, 50, 75])
    return float(med), float(q1), float(q3)


def summarize(runs: list[Run], f_target: float, bounds: Any, x_opt: np.ndarray | None) -> dict[str, Any]:
    lo, hi = parse_bounds(bounds)
    evals, rounds, found = [], [], []
    for r in runs:
        hit = np.flatnonzero(r.f_trace <= f_target)
        if hit.size:
            evals.append(int(hit[0]) + 1)
            rounds.append(int(r.rounds_of_eval[hit[0]]))
        if x_opt is not None:
            found.append(bool(np.max(np.abs(r.x_best - x_opt) / (hi - lo)) <= 0.01))
    return {
        "runs": len(runs),
        "f_target": f_target,
        "reach": len(evals) / len(runs) if runs else math.nan,
        "evals": _med_iqr(evals),
        "rounds": _med_iqr(rounds),
        "found": float(np.mean(found)) if found else math.nan,
        "stop": float(np.median([r.nfev for r in runs])) if runs else math.nan,
        "f_final": float(np.median([r.f_best for r in runs])) if runs else math.nan,
        "seconds": float(np.sum([r.seconds for r in runs])),
    }


def compare(fun: Callable[[np.ndarray], float], bounds: Any, budget: int = 5000,
            seeds: Iterable[int] = range(20), *, methods: Sequence[str] = METHODS,
            f_target: float | None = None, x_opt: Any = None, n_parallel: int = 4,
            n_jobs: int = 1) -> dict[str, dict[str, Any]]:
    """Run every method from every seed with ``budget`` evaluations; return stats per method.

    ``f_target`` None: best value of all runs plus 1 % of its magnitude (plus 1e-12).
    ``x_opt``: the known optimum, for the ``found`` share.  ``n_jobs > 1`` runs the
    (method, seed) runs in a process pool (``fun`` must be picklable).
    """
    seeds = list(seeds)
    jobs = [(m, fun, bounds, int(budget), int(s), int(n_parallel)) for m in methods for s in seeds]
    if n_jobs > 1:
        with ProcessPoolExecutor(n_jobs) as pool:
            runs = list(pool.map(_run_job, jobs))
    else:
        runs = [_run_job(j) for j in jobs]
    if f_target is None:
        best = min(float(np.min(r.f_trace)) for r in runs if r.f_trace.size)
        f_target = best + 0.01 * abs(best) + 1e-12
    xo = None if x_opt is None else np.asarray(x_opt, dtype=float)
    return {m: summarize([r for r in runs if r.method == m], f_target, bounds, xo) for m in methods}


# --------------------------------------------------------------------------
# Complex-RF settings and Complex-RFP speed-up
# --------------------------------------------------------------------------


def _found(x: np.ndarray, prob: Problem) -> bool:
    lo, hi = parse_bounds(prob.bounds)
    return bool(np.max(np.abs(x - prob.x_opt) / (hi - lo)) <= 0.01)


def _settings_job(job: tuple) -> tuple[str, str, int, bool, int]:
    prob_name, label, kw, seed = job
    prob = {p.name: p for p in test_problems()}[prob_name]
    res = minimize_complex(prob.fun, prob.bounds, seed=seed, **kw)
    return prob_name, label, seed, _found(res.x, prob), res.nfev


def settings_table(seeds: Sequence[int], n_jobs: int = 1) -> str:
    """Found-rate of serial Complex-RF per problem for a few complex sizes / tolerances."""
    jobs = []
    for prob in test_problems():
        m = len(prob.bounds)
        variants = [("defaults (m+2 points)", {}), ("2m points, x_tol 1e-6", {"n_points": 2 * m, "x_tol": 1e-6}),
                    ("10m points", {"n_points": 10 * m}), ("20m points", {"n_points": 20 * m})]
        for label, kw in variants:
            jobs += [(prob.name, label, kw, int(s)) for s in seeds]
    if n_jobs > 1:
        with ProcessPoolExecutor(n_jobs) as pool:
            out = list(pool.map(_settings_job, jobs))
    else:
        out = [_settings_job(j) for j in jobs]
    labels = list(dict.fromkeys(j[1] for j in jobs))
    lines = ["| problem | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for prob in test_problems():
        cells = []
        for label in labels:
            rs = [o for o in out if o[0] == prob.name and o[1] == label]
            cells.append(f"{100 * np.mean([o[3] for o in rs]):.0f} % ({np.median([o[4] for o in rs]):.0f})")
        lines.append(f"| {prob.name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _speedup_job(job: tuple) -> tuple[str, str, int, int, int, int]:
    prob_name, strategy, p, seed = job
    prob = {q.name: q for q in test_problems() + [_ellipsoid10()]}[prob_name]
    if strategy == "serial":
        res = minimize_complex(prob.fun, prob.bounds, seed=seed)
    else:
        res = minimize_complex_parallel(prob.fun, prob.bounds, seed=seed, n_parallel=p, strategy=strategy)
    return prob_name, strategy, p, res.nrounds, res.nfev, int(_found(res.x, prob))


ELLIPSOID_C = np.linspace(0.25, 0.85, 10)
ELLIPSOID_W = np.linspace(1.0, 30.0, 10)


def ellipsoid10(x: np.ndarray) -> float:
    """A 10-variable ill-scaled bowl in [0.2, 0.9]^10: the size of the identification problem."""
    return float(np.sum(ELLIPSOID_W * (x - ELLIPSOID_C) ** 2))


def _ellipsoid10() -> Problem:
    return Problem("ellipsoid-10", ellipsoid10, [(0.2, 0.9)] * 10, ELLIPSOID_C, 1e-4)


def speedup_table(seeds: Sequence[int], ps: Sequence[int] = (2, 4, 8), n_jobs: int = 1) -> str:
    """Median rounds (and evaluations) to the stop, serial vs. Complex-RFP strategies."""
    probs = [p.name for p in test_problems()] + ["ellipsoid-10"]
    cols = [("serial", 1)] + [(sname, p) for sname in ("speculative", "multidirection") for p in ps]
    jobs = [(pn, sname, p, int(s)) for pn in probs for sname, p in cols for s in seeds]
    if n_jobs > 1:
        with ProcessPoolExecutor(n_jobs) as pool:
            out = list(pool.map(_speedup_job, jobs))
    else:
        out = [_speedup_job(j) for j in jobs]
    head = ["serial"] + [f"{'spec' if sn == 'speculative' else 'multidir'} x{p}" for sn, p in cols[1:]]
    lines = ["| problem | " + " | ".join(head) + " |", "|---|" + "---|" * len(head)]
    for pn in probs:
        cells = []
        for sname, p in cols:
            rs = [o for o in out if o[0] == pn and o[1] == sname and o[2] == p]
            cells.append(f"{np.median([o[3] for o in rs]):.0f} / {np.median([o[4] for o in rs]):.0f}"
                         f" / {100 * np.mean([o[5] for o in rs]):.0f} %")
        lines.append(f"| {pn} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


# --------------------------------------------------------------------------
# output
# --------------------------------------------------------------------------


def _fmt_miq(t: tuple[float, float, float]) -> str:
    med, q1, q3 = t
    if math.isnan(med):
        return "-"
    return f"{med:.0f} [{q1:.0f}-{q3:.0f}]"


def format_table(results: dict[str, dict[str, dict[str, Any]]], markdown: bool = False) -> str:
    head = ["problem", "method", "reach", "evals to target, median [IQR]", "rounds to target",
            "found", "stop (evals)", "f_final"]
    rows = []
    for prob, per_method in results.items():
        for meth, s in per_method.items():
            rows.append([
                prob, meth, f"{100 * s['reach']:.0f} %", _fmt_miq(s["evals"]), _fmt_miq(s["rounds"]),
                "-" if math.isnan(s["found"]) else f"{100 * s['found']:.0f} %",
                f"{s['stop']:.0f}", f"{s['f_final']:.3g}",
            ])
    if markdown:
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
        return "\n".join(lines)
    widths = [max(len(str(x)) for x in col) for col in zip(head, *rows)]
    fmt = "  ".join("{:<%d}" % w for w in widths)
    return "\n".join([fmt.format(*head), fmt.format(*["-" * w for w in widths])] + [fmt.format(*r) for r in rows])


def write_markdown(path: Path, results: dict, args: argparse.Namespace, seconds: float,
                   extra: str = "") -> None:
    tmap = {p: next(iter(r.values()))["f_target"] for p, r in results.items()}
    if len(set(tmap.values())) == 1:
        targets = f"f_target = {next(iter(tmap.values())):g} for every problem"
    else:
        targets = ", ".join(f"{p}: {t:g}" for p, t in tmap.items())
    text = f"""# Optimiser benchmark

Written by `benchmarks/bench_optimizers.py` ({_dt.date.today().isoformat()}, Python
{platform.python_version()}, {platform.machine()}, {seconds:.0f} s wall time); rerun it to
refresh these numbers.  Settings: budget {args.budget} evaluations per run, seeds
0-{args.seeds - 1} ({args.seeds} runs per method and problem), {args.n_parallel} evaluations per
round for the parallel counts.  Methods with their defaults: Complex-RF (`minimize_complex`,
m + 2 points, alpha 1.3, rfak 0.3, gamma 0.3, f_tol 1e-6, x_tol 1e-4), Complex-RFP
(`minimize_complex_parallel`, speculative and multi-direction strategies),
`scipy.optimize.differential_evolution` (popsize 15, `updating="deferred"`, no polish,
maxiter from the budget), CMA-ES (`cma`, variables scaled to [0, 1], sigma0 0.3, random x0).

Columns: **reach** share of runs whose best value reached the target f <= f_target
({targets}); **evals to target** evaluations until then, median and interquartile range over
the runs that reached it (for Complex-RFP only evaluations the method used count as
reaching, all count as cost); **rounds to target** the same in wall-clock rounds with
{args.n_parallel} workers (DE / CMA-ES: ceil(population / {args.n_parallel}) rounds per
generation); **found** share of runs whose final point is within 1 % of the bound range of
the optimum in every coordinate; **stop** median evaluations until the method stopped on
its own criteria or the budget; **f_final** median best value.

{format_table(results, markdown=True)}
{extra}
Reading it: see `docs/complex_rf.md` (section "Measured performance").
"""
    path.write_text(text)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--budget", type=int, default=5000)
    ap.add_argument("--n-parallel", type=int, default=4)
    ap.add_argument("--n-jobs", type=int, default=1, help="processes running the benchmark itself")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--problems", default="", help="comma-separated subset of the test problems")
    ap.add_argument("--out", default=str(ROOT / "docs" / "optimizer_benchmark.md"))
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--extra-seeds", type=int, default=50,
                    help="seeds for the Complex-RF settings and speed-up tables (0 = skip them)")
    args = ap.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m]
    wanted = set(p for p in args.problems.split(",") if p)
    t0 = time.perf_counter()
    results: dict[str, dict[str, dict[str, Any]]] = {}
    for prob in test_problems():
        if wanted and prob.name not in wanted:
            continue
        results[prob.name] = compare(prob.fun, prob.bounds, args.budget, range(args.seeds), methods=methods,
                                     f_target=prob.f_target, x_opt=prob.x_opt, n_parallel=args.n_parallel,
                                     n_jobs=args.n_jobs)
        print(format_table({prob.name: results[prob.name]}), flush=True)
        print(flush=True)
    print(format_table(results))
    extra = ""
    if args.extra_seeds > 0:
        seeds = range(args.extra_seeds)
        st = settings_table(seeds, args.n_jobs)
        print("\nComplex-RF found-rate by setting\n" + st, flush=True)
        sp = speedup_table(seeds, n_jobs=args.n_jobs)
        print("\nrounds / evaluations / found\n" + sp, flush=True)
        extra = f"""
## Complex-RF: found-rate by setting

Serial `minimize_complex`, budget 5000, seeds 0-{args.extra_seeds - 1}: share of runs whose final
point is within 1 % of the bound range of the optimum in every coordinate, and (in
brackets) the median number of evaluations until the method stopped.

{st}

## Complex-RFP: rounds

Median wall-clock rounds / median evaluations (all, including discarded speculative
ones) / found-rate, until the method stopped, seeds 0-{args.extra_seeds - 1}, budget 5000
(used evaluations).  `spec xP`: speculative strategy with P evaluations per round (the
same run as serial, so the same found-rate); `multidir xP`: multi-direction strategy
(moves at most half the complex at once, so P is capped at n_points // 2).
`ellipsoid-10` is a 10-variable ill-scaled bowl in [0.2, 0.9]^10 (the size of the
identification problem).

{sp}
"""
    seconds = time.perf_counter() - t0
    if not args.no_write:
        write_markdown(Path(args.out), results, args, seconds, extra)
        print(f"\nwritten {args.out} ({seconds:.0f} s)")
    return 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    raise SystemExit(main())
