#!/usr/bin/env python3
"""What the solver's tolerance costs and what it changes on a transient
record: per tolerance and Runge-Kutta pair, the CPU of one simulation of a
recovery start-stop record at its true values, the solver's error against a
reference (DOP853 at 1e-9) in noise levels, the change of f, and the shift
of every design variable that error causes in the fit, linearised:
dx = (J' W J)^-1 J' W e, J the central Jacobian at the truth, W the
likelihood's 1 / sigma^2, e the error. A shift far below the CoRs' interval
(about 0.01) and the 0.03 the recovery table asks is a tolerance the
identification can use.

    .venv/bin/python benchmarks/bench_transient_tolerance.py --measurements 20,1,9 \\
        --json benchmarks/results/transient_tolerance.json
    .venv/bin/python benchmarks/bench_transient_tolerance.py --table --json benchmarks/results/transient_tolerance.json
    .venv/bin/python benchmarks/bench_transient_tolerance.py --doc --json benchmarks/results/transient_tolerance.json
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench_common import ROOT, write_between  # noqa: E402
from profile_identification import records_of  # noqa: E402
from identification import Settings  # noqa: E402
from identification.objective.jacobian import jacobian  # noqa: E402
from identification.pipeline.driver import build_problem  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS, symbol  # noqa: E402
from lss_fmu.rig import load_truth, parse_numbers, true_design_values  # noqa: E402

TOLERANCES = (1e-6, 3e-6, 1e-5, 3e-5, 1e-4)
METHODS = {0: "DOPRI5", 1: "DOP853"}
REFERENCE = (1e-9, 1)
BASE_TOL = 1e-6   # the CPU column's unit: DOPRI5 at the tolerance the identification used before
REPEATS = 3   # CPU: the least of this many runs


def at(p, tol: float, method: int):
    q = dataclasses.replace(p, tolerance=tol, fixed={**p.fixed, "solver.method": method})
    q.sim = p.sim
    return q


def cpu_of(q, x) -> float:
    q.simulate(x)   # the relaxed chain kept: the CPU of a run, as the identification's steps see it
    best = np.inf
    for k in range(REPEATS):
        xk = np.array(x, float)
        xk[0] += 1e-12 * (k + 1)   # another point: not the problem's memo
        c = time.process_time()
        q.simulate(xk)
        best = min(best, time.process_time() - c)
    return best


def counts_of(q, x) -> dict:
    """The solver's accepted steps, rejected steps and right-hand sides of one
    run past its start (the relaxed chain restored): the cost of a simulation
    that the machine's load does not move."""
    sim = q.sim()
    start, seen = sim.start, {}
    names = ("solver.n_steps", "solver.n_rejected", "solver.n_rhs")

    def counted(*args, **kwargs):
        start(*args, **kwargs)
        seen.update({n: sim.get(n) for n in names})

    sim.start = counted
    try:
        xk = np.array(x, float)
        xk[0] += 1e-11   # not the memo's point
        q.simulate(xk)
    finally:
        del sim.start
    return {n.split(".")[1]: int(sim.get(n) - seen[n]) for n in names}


def measure(number: int, work: Path, tolerances=TOLERANCES, methods=tuple(METHODS)) -> dict:
    rec = records_of(work, number, 1)
    p = build_problem(rec, "LW", Settings())
    truth = true_design_values(load_truth(Path(rec[0].path)))
    x = np.array([truth[n] for n in p.free])
    w = 1.0 / p.noise ** 2
    ref = at(p, *REFERENCE).simulate(x)
    base = at(p, p.tolerance, 0)
    y0 = base.simulate(x)
    J, _, _ = jacobian(base, x, y0, weights=w)
    A = (J * np.sqrt(w)[None, :, None]).reshape(-1, len(x))
    rows = []
    for method in methods:
        for tol in tolerances:
            q = at(p, tol, method)
            y = q.simulate(x)
            e = (y - ref) * np.sqrt(w)
            dx, *_ = np.linalg.lstsq(A, e.ravel(), rcond=None)
            rows.append({"method": METHODS[method], "tol": tol, "cpu_s": cpu_of(q, x), **counts_of(q, x),
                         "error_sigma": float(np.sqrt(np.mean(e ** 2))), "f": float(q(x)),
                         "shift": {symbol(n): float(d) for n, d in zip(p.free, dx)}})
    return {"measurement": number, "layout": rec[0].layout, "window_s": float(p.times[-1]),
            "default_tolerance": p.tolerance, "f_reference": float(at(p, *REFERENCE)(x)), "rows": rows}


def table(entry: dict) -> str:
    cors = [symbol(n) for n in CORS]
    out = []
    for m in entry["results"]:
        # the unit: DOPRI5 at BASE_TOL where the run has it, else at the run's finest DOPRI5 tolerance
        dopri = [r for r in m["rows"] if r["method"] == "DOPRI5"]
        base = next((r for r in dopri if r["tol"] == BASE_TOL), None) or min(dopri, key=lambda r: r["tol"])
        counted = all("n_rhs" in r for r in m["rows"])
        out.append(f"\n**{m['layout']}** (measurement {m['measurement']}, {m['window_s']:.2g} s, f at the truth "
                   f"{m['f_reference']:.4f} with the reference)\n")
        out.append(f"| pair | tolerance | CPU / DOPRI5 at {base['tol']:g} | "
                   + (f"steps, right-hand sides (/ DOPRI5 at {base['tol']:g}) | " if counted else "")
                   + "error, sigma | f | " + " | ".join(f"{c} shift" for c in cors) + " |")
        out.append("|" + "---|" * (5 + counted + len(cors)))
        for r in m["rows"]:
            mark = " (the run's default)" if r["method"] == "DOPRI5" and r["tol"] == m["default_tolerance"] else ""
            cost = f"{r['n_steps']}, {r['n_rhs']} ({r['n_rhs'] / base['n_rhs']:.2f}) | " if counted else ""
            out.append(f"| {r['method']} | {r['tol']:g}{mark} | {r['cpu_s'] / base['cpu_s']:.2f} | {cost}"
                       f"{r['error_sigma']:.4f} | {r['f']:.4f} | "
                       + " | ".join(f"{r['shift'][c]:+.4f}" for c in cors) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--measurements", default="20,1,9")
    ap.add_argument("--work", default="build/bench_recovery")
    ap.add_argument("--json", default=None)
    ap.add_argument("--tolerances", default=",".join(f"{t:g}" for t in TOLERANCES),
                    help="comma-separated solver tolerances (default %(default)s)")
    ap.add_argument("--methods", default=",".join(METHODS.values()),
                    help="comma-separated pairs among " + ", ".join(METHODS.values()))
    ap.add_argument("--table", action="store_true", help="print the Markdown tables of --json and stop")
    ap.add_argument("--doc", action="store_true", help="write them into docs/benchmarks.md and stop")
    ap.add_argument("--tag", default="tolerance", help="the docs/benchmarks.md block --doc writes (default %(default)s)")
    args = ap.parse_args(argv)
    if args.table or args.doc:
        text = table(json.loads(Path(args.json).read_text()))
        if args.doc:
            write_between(ROOT / "docs" / "benchmarks.md", args.tag, text)
        else:
            print(text)
        return 0
    names = {v: k for k, v in METHODS.items()}
    try:
        tolerances = tuple(float(t) for t in args.tolerances.split(","))
        methods = tuple(names[m.strip()] for m in args.methods.split(","))
    except (ValueError, KeyError) as e:
        ap.error(f"--tolerances {args.tolerances!r} / --methods {args.methods!r}: {e}")
    results = [measure(n, Path(args.work), tolerances, methods) for n in parse_numbers(args.measurements)]
    entry = {"command": " ".join(sys.argv), "reference": {"tol": REFERENCE[0], "method": METHODS[REFERENCE[1]]},
             "results": results}
    if args.json:
        write_json_atomic(args.json, entry)
    print(table(entry))
    return 0


if __name__ == "__main__":
    sys.exit(main())
