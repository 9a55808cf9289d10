#!/usr/bin/env python3
"""The profile of one design variable of a stored recovery result (issue 17).

A result of bench_recovery.py (its mNN.json: the records, the window, the
point found) is taken up again: along a grid of the variable, every other
free variable refitted by the pipeline's Levenberg-Marquardt (central
differences, as identify.local_stage), each grid point started from its
neighbour's fit, outwards from the estimate. The profile's statistic is the
likelihood ratio in the metric of the Jacobian interval
(identification.objective.uncertainty: each channel's variance and effective sample
count from the residual at the estimate),

    L(g) = sum_j w_j sum_i (r_ij(g)^2 - r_ij(estimate)^2),

so that a linear problem gives L = (g - estimate)^2 / sd^2; the 95 %
profile interval is where L lies within 3.84 of its minimum (chi^2, one degree
of freedom; the estimate is refitted too and need not be that minimum). Where
the Jacobian interval says a CoR is determined, the profile shows whether
it is, over the whole box and not only at the estimate.

    .venv/bin/python benchmarks/profile_cor.py \\
        build/bench_recovery/start-stop/likelihood/grown/shrink/ten_free_k3_auto_r1/m22.json \\
        --variable e_JR --points 8 --json benchmarks/results/profile_m22_e_JR.json \\
        --figure docs/figures/profile_m22_e_JR.png
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench_common import code_version  # noqa: E402
from identification.pipeline.identify import REFINE_STEP  # noqa: E402
from identification.objective.joint import JointProblem  # noqa: E402
from identification.objective.problem import from_measurement, tared  # noqa: E402
from identification.pipeline.refine import refine  # noqa: E402
from identification.objective.uncertainty import information_weights  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import SYMBOL  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import load_truth  # noqa: E402

CHI2_95 = 3.841459   # chi^2 with one degree of freedom, 95 %


def records_of(result: dict) -> list:
    """The measurement folders of a stored row: the record, then its repeats (data_rK beside data)."""
    first = Path(result["measurement_dir"])
    folders = [first] + [first.parent.parent / f"data_r{k}" / first.name for k in range(1, result.get("records", 1))]
    for f in folders:
        if not (f / "meta.json").exists():
            raise FileNotFoundError(f"{f}: record of {result['measurement']} not found (meta.json missing)")
    return folders


def problem_of(result: dict, tare: bool, objective: str):
    """The row's problem at its chosen window (the joint one and its records)."""
    window = float(result["window_s"])
    parts = [from_measurement(load_measurement(f), result["model"], window=window, tare=tare,
                              objective=objective) for f in records_of(result)]
    return (parts[0] if len(parts) == 1 else JointProblem(parts)), parts


def ratio_stat(problem, sim: np.ndarray, w: np.ndarray, r0sq: np.ndarray) -> float:
    r = tared(problem.samples - sim, problem.tare)
    return float(np.sum(w * (np.sum(r ** 2, axis=0) - r0sq)))


def crossing(g: np.ndarray, L: np.ndarray, k0: int, step: int) -> float:
    """Where L rises through CHI2_95 going from index k0 by `step` (linear
    between grid points); the box's edge if it never does."""
    k = k0
    while 0 <= k + step < len(g):
        if L[k + step] > CHI2_95:
            a, b = L[k], L[k + step]
            return float(g[k] + (g[k + step] - g[k]) * (CHI2_95 - a) / (b - a)) if b > a else float(g[k + step])
        k += step
    return float(g[k])


def interval_of(g: np.ndarray, L: np.ndarray) -> tuple:
    """The 95 % profile interval: L measured from the profile's own minimum
    (the estimate need not be it: a refinement stops a little short)."""
    kmin = int(np.argmin(L))
    Lm = L - L[kmin]
    return crossing(g, Lm, kmin, -1), crossing(g, Lm, kmin, +1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("result", type=Path, help="a bench_recovery row (mNN.json)")
    ap.add_argument("--variable", default="e_JR", help="the symbol of the variable profiled (e_JA, e_JR, ...)")
    ap.add_argument("--points", type=int, default=8, help="grid points over the bounds (the estimate added)")
    ap.add_argument("--evals", type=int, default=150, help="refit budget per grid point (simulations)")
    ap.add_argument("--f-rtol", type=float, default=1e-6,
                    help="a refit stops when a step gains less than this share of f (the pipeline's 1e-4 is "
                         "about one unit of L on a record at the noise: too coarse for a profile)")
    ap.add_argument("--objective", default="likelihood", choices=("likelihood", "pointwise"),
                    help="the row's objective (bench_recovery --objective)")
    ap.add_argument("--no-tare", action="store_true", help="the row was computed with bench_recovery --no-tare")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--figure", type=Path)
    args = ap.parse_args(argv)
    if args.points < 2 or args.evals < 1:
        ap.error(f"--points {args.points} / --evals {args.evals}: at least 2 points and 1 simulation")
    result = json.loads(args.result.read_text())
    name = next((n for n in result["free"] if SYMBOL.get(n) == args.variable or n == args.variable), None)
    if name is None:
        ap.error(f"{args.variable}: not a free variable of {args.result} ({', '.join(result['free'])})")
    c0, t0 = time.process_time(), time.time()
    p, parts = problem_of(result, not args.no_tare, args.objective)
    x_hat = np.array([result["x"][n] for n in p.free])
    sim0 = p.simulate(x_hat)
    r0 = tared(p.samples - sim0, p.tare)
    w = information_weights(r0)
    r0sq = np.sum(r0 ** 2, axis=0)
    f_hat = float(p(x_hat))
    if not np.isclose(f_hat, result["f"], rtol=1e-6):
        for q in parts:
            q.sim.close()
        ap.error(f"{args.result}: f = {f_hat:.8g} at its point here, {result['f']:.8g} stored: the row was computed "
                 f"with another objective, tare or code (--objective, --no-tare)")
    lo, hi = result["bounds"][name]
    grid = np.union1d(np.linspace(lo, hi, args.points), [result["x"][name]])
    k0 = int(np.argmin(np.abs(grid - result["x"][name])))
    others = [n for n in p.free if n != name]
    base = [n for n in others if "@" not in n]

    def refit(value: float, start: dict) -> dict:
        """The others refitted with the variable held at `value`, from `start`."""
        x0 = {**start, name: float(value)}
        sub = JointProblem(parts, free=base, x0=x0) if isinstance(p, JointProblem) \
            else dataclasses.replace(p, free=tuple(base), x0=x0)
        ref = refine(sub, np.array([x0[n] for n in sub.free]), max_evals=args.evals, rel_step=REFINE_STEP,
                     f_rtol=args.f_rtol, central=True)
        full = {**sub.values(ref.x), name: float(value)}
        xf = np.array([full[n] for n in p.free])
        sim = ref.sim if ref.sim is not None else p.simulate(xf)
        row = {"value": float(value), "f": float(p(xf)), "L": ratio_stat(p, sim, w, r0sq), "nfev": int(ref.nfev),
               "x": full}
        print(f"{args.variable} = {value:.4f}: f = {row['f']:.5g}, L = {row['L']:.4g} ({ref.nfev} simulations)",
              file=sys.stderr)
        return row

    # the estimate refitted too: a refinement that stopped short leaves it above its own profile
    rows = {k0: refit(grid[k0], dict(result["x"]))}
    for step in (-1, 1):   # outwards from the estimate, each point from its neighbour's fit
        start = rows[k0]["x"]
        for k in range(k0 + step, -1 if step < 0 else len(grid), step):
            rows[k] = refit(grid[k], start)
            start = rows[k]["x"]
    for q in parts:
        q.sim.close()
    g = np.array([rows[k]["value"] for k in sorted(rows)])
    L = np.array([rows[k]["L"] for k in sorted(rows)])
    kmin = int(np.argmin(L))
    lower, upper = interval_of(g, L)
    truth = load_truth(records_of(result)[0])["cor"].get(args.variable) if args.variable.startswith("e_") else None
    iv = (result.get("interval") or {}).get(args.variable) or {}
    out = {"result": str(args.result), "measurement": result["measurement"], "variable": args.variable,
           "window_s": result["window_s"], "estimate": result["x"][name], "truth": truth, "f_estimate": f_hat,
           "jacobian_interval": iv, "grid": g.tolist(), "L": L.tolist(), "f": [rows[k]["f"] for k in sorted(rows)],
           "nfev": [rows[k]["nfev"] for k in sorted(rows)], "points": [rows[k]["x"] for k in sorted(rows)],
           "profile_interval": {"lower": lower, "upper": upper, "chi2": CHI2_95,
                                "width_of_range": (upper - lower) / (hi - lo)},
           "profile_minimum": float(g[kmin]),
           "L_truth": None if truth is None else float(np.interp(truth, g, L)), "cpu_s": time.process_time() - c0, "wall_s": time.time() - t0,
           "code": code_version()}
    print(json.dumps({k: out[k] for k in ("variable", "estimate", "truth", "L_truth", "profile_minimum", "profile_interval",
                                          "cpu_s")}, indent=1))
    if args.json:
        write_json_atomic(args.json, out)
    if args.figure:
        plot(out, args.figure)
    return 0


def plot(out: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    ax.plot(out["grid"], out["L"], "o-", color="C0", label="profile (others refitted)")
    iv = out["jacobian_interval"]
    if iv.get("sd"):
        g = np.linspace(min(out["grid"]), max(out["grid"]), 200)
        ax.plot(g, ((g - out["estimate"]) / iv["sd"]) ** 2, "--", color="C1",
                label=f"Jacobian: ((x - est) / sd)^2, sd {iv['sd']:.3g}")
    ax.axhline(min(out["L"]) + CHI2_95, color="0.5", lw=0.8, label="95 %: profile minimum + chi^2(1)")
    if out["truth"] is not None:
        ax.axvline(out["truth"], color="C2", lw=1.2, label=f"truth {out['truth']:.3f}")
    pi = out["profile_interval"]
    ax.axvspan(pi["lower"], pi["upper"], color="C0", alpha=0.12, label="profile 95 % interval")
    lo = min(min(out["L"]), 0.0) - 1.0
    ax.set_ylim(lo, lo + 1.0 + 4 * CHI2_95)   # the interval's neighbourhood; far points run off the top
    ax.set_xlabel(out["variable"])
    ax.set_ylabel("likelihood ratio L")
    ax.set_title(f"{out['measurement']}, {out['window_s']:g} s")
    ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
