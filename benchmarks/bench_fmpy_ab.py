#!/usr/bin/env python3
"""Two FMUs side by side through fmpy, in one process: cart-seconds per
CPU-second at 300 Hz with the FMU's default settings.

Each run is `ChainSimulator.simulate` of `--time` s from the start (the 7
force channels read at every communication point, start-up included, as in
bench_fmpy.py), timed by the process's CPU clock. The two FMUs run in turn,
A B A B ..., `--pairs` pairs per layout after one untimed run of each, so
that a drift of the machine's speed falls on both; the figure is the ratio
B / A of the speeds pair by pair (its median, min and max), beside each
FMU's median speed. `--set-b` gives the second FMU's runs parameters of
their own (a proposed setting against the first FMU's defaults).

Usage::

    .venv/bin/python benchmarks/bench_fmpy_ab.py --a build/before/LSSChain.fmu --b build/LSSChain.fmu \\
        --layouts layout7 layout1 layout3 --pairs 7 --json out.json
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from bench_common import COMM, machine
from lss_fmu.atomic import write_json_atomic
from lss_fmu.runner import ChainSimulator
from lss_fmu.variables import FORCE_CHANNELS


def run(sim, layout, t_end, params=None):
    t0 = time.process_time()
    df = sim.simulate(t_end, COMM, {"layout.name": layout, **(params or {})}, FORCE_CHANNELS)
    cpu = time.process_time() - t0
    return cpu, df[FORCE_CHANNELS].to_numpy(), int(sim.get("chain.n_carts"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--a", required=True, help="the first FMU (the one before)")
    ap.add_argument("--b", required=True, help="the second FMU (the one after)")
    ap.add_argument("--layouts", nargs="+", default=["layout7", "layout1"])
    ap.add_argument("--time", type=float, default=5.0)
    ap.add_argument("--pairs", type=int, default=7)
    ap.add_argument("--set-b", nargs="*", default=[], metavar="NAME=VALUE",
                    help="parameters for the second FMU's runs only (e.g. solver.method=1 solver.tolerance=3e-3)")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    pb = {k: float(v) for k, v in (kv.split("=", 1) for kv in a.set_b)}
    res = dict(machine=machine(), a=a.a, b=a.b, b_params=pb, time=a.time, pairs=a.pairs, layouts={})
    with ChainSimulator(a.a) as sa, ChainSimulator(a.b) as sb:
        for layout in a.layouts:
            run(sa, layout, min(a.time, 0.5))  # warm-up: libraries, caches
            run(sb, layout, min(a.time, 0.5), pb)
            ca, cb = [], []
            for _ in range(a.pairs):
                t, xa, n = run(sa, layout, a.time)
                ca.append(t)
                t, xb, _ = run(sb, layout, a.time, pb)
                cb.append(t)
            ca, cb = np.array(ca), np.array(cb)
            speed_a, speed_b = n * a.time / ca, n * a.time / cb
            ratio = speed_b / speed_a
            diff = float(np.max(np.abs(xa - xb)))
            rng = float(np.max(xa) - np.min(xa))
            r = dict(carts=n, cpu_a=ca.tolist(), cpu_b=cb.tolist(), speed_a_median=float(np.median(speed_a)),
                     speed_b_median=float(np.median(speed_b)), ratio_median=float(np.median(ratio)),
                     ratio_min=float(np.min(ratio)), ratio_max=float(np.max(ratio)), max_abs_diff_N=diff,
                     range_N=rng)
            res["layouts"][layout] = r
            setting = "defaults" + (", B with " + " ".join(a.set_b) if a.set_b else "")
            print(f"{layout} ({n} carts, {a.time:g} s at 300 Hz, {setting}): A {r['speed_a_median']:.0f}, "
                  f"B {r['speed_b_median']:.0f} cart-s per CPU-s (medians of {a.pairs}); B/A pair by pair: median "
                  f"{r['ratio_median']:.3f} (min {r['ratio_min']:.3f}, max {r['ratio_max']:.3f}); "
                  f"outputs differ by at most {diff:.3g} N (range {rng:.3g} N)", flush=True)
    if a.json:
        write_json_atomic(a.json, res, indent=1)
    return res


if __name__ == "__main__":
    main()
