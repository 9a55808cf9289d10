#!/usr/bin/env python3
"""Why a grown identification starts wrong: its first window against the truth.

`identify_grown` finds its start on the record's first 0.3 s with the
complex and carries it along growing windows. Where that first fit is
already above the noise (m15, m21 of the recovery set's start-stops) nothing
later recovers. This probe, on one recovery record, prints S per sample on
the first window (about 1 at the noise):

- at the truth, and with the trigger point s_M moved by a few millimetres
  (the width of the truth's valley);
- after the complex from each of `--seeds` (300 evaluations as the pipeline);
- after Levenberg-Marquardt from the first seed's point with s_M put at the
  truth (whether s_M alone is what the complex misses);
- with `--scan`, per seed, a remedy tried and not adopted: the complex on
  half the first window, s_M scanned over its bounds at 3 mm with the
  others held, Levenberg-Marquardt from the scan's six lowest minima, then
  on the first window.

    .venv/bin/python benchmarks/probe_first_window.py m21 --seeds 0,1,2

Reads the answer files, so it is a benchmark, never part of the pipeline.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from identification.pipeline.base_polish import STEP  # noqa: E402
from identification.pipeline.growing import FIRST  # noqa: E402
from identification.pipeline.identify import identify  # noqa: E402
from identification.objective.problem import from_measurement, tared  # noqa: E402
from identification.pipeline.refine import refine  # noqa: E402
from identification.pipeline.windowing import truncated  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import load_truth, true_design_values  # noqa: E402

SHIFTS = (-0.03, -0.01, -0.005, 0.0, 0.005, 0.01, 0.03)   # m, s_M moved from the truth


def weighted_S(q, x, w) -> float:
    """S in the declared noise's metric (sum of squared tared residuals over sigma^2); inf where x does
    not simulate."""
    try:
        return float(np.sum(tared(q.samples - q.simulate(x), q.tare) ** 2 * w))
    except Exception:
        return np.inf


def scan(q, k: int, w, evals: int, seed: int, step: float = 0.003, minima: int = 6) -> np.ndarray:
    """The point on q (the first window) found from half of it: the complex
    there, variable k scanned over its bounds, Levenberg-Marquardt from the
    lowest local minima, then on q."""
    qh = truncated(q, q.times[0] + 0.5 * (q.times[-1] - q.times[0]))
    x = np.asarray(identify(qh, max_evals=evals, seed=seed, progress=False).x, float)
    lo, hi = qh.bounds_array[k]
    grid = np.arange(lo, hi + 1e-12, step)
    vals = []
    for s in grid:
        y = x.copy()
        y[k] = s
        vals.append(weighted_S(qh, y, w))
    low = [i for i in range(len(grid)) if (i == 0 or vals[i] <= vals[i - 1])
           and (i == len(grid) - 1 or vals[i] <= vals[i + 1])]
    best, fbest = x, weighted_S(qh, x, w)
    for i in sorted(low, key=lambda i: vals[i])[:minima]:
        y = x.copy()
        y[k] = grid[i]
        r = refine(qh, y, max_evals=60, central=True, channel_weights=w, rel_step=STEP)
        if r.f < fbest:
            best, fbest = np.asarray(r.x, float), float(r.f)
    return np.asarray(refine(q, best, max_evals=60, central=True, channel_weights=w, rel_step=STEP).x, float)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("record", help="a recovery record, e.g. m21")
    ap.add_argument("--data", default="build/bench_recovery/start-stop/data")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--evals", type=int, default=300)
    ap.add_argument("--window", type=float, default=2.5)
    ap.add_argument("--scan", action="store_true", help="try the scan on half the first window per seed")
    ap.add_argument("--first", type=float, default=FIRST, help="the first window, s (the pipeline's: %(default)s)")
    args = ap.parse_args(argv)
    m = load_measurement(Path(args.data) / args.record)
    p = from_measurement(m, "LW", window=args.window, tare=True, objective="likelihood")
    q = truncated(p, p.times[0] + args.first)
    w = 1.0 / np.asarray(p.noise, float) ** 2

    def S(x) -> float:   # per sample: about 1 at the noise
        return weighted_S(q, x, w) / q.samples.size

    truth = true_design_values(load_truth(m))
    xt = np.array([truth[k] for k in q.free])
    k = q.free.index("trigger.s_M")
    for d in SHIFTS:
        y = xt.copy()
        y[k] += d
        print(f"truth, s_M {d * 1000:+5.0f} mm: S per sample {S(y):.3f}")
    first = None
    for seed in (int(s) for s in args.seeds.split(",")):
        c0 = time.process_time()
        x = np.asarray(identify(q, max_evals=args.evals, seed=seed, progress=False).x, float)
        first = x if first is None else first
        err = ", ".join(f"{n.split('.')[-1]} {v - truth[n]:+.3g}" for n, v in zip(q.free, x)
                        if n.startswith("contact.") or n == "trigger.s_M")
        print(f"complex, seed {seed}: S per sample {S(x):.3f} ({err}; {time.process_time() - c0:.0f} CPU-s)")
        if args.scan:
            xs = scan(q, k, w, args.evals, seed)
            print(f"  scan on {q.times[-1] / 2:.3g} s, seed {seed}: S per sample {S(xs):.3f} "
                  f"(s_M {xs[k] - truth['trigger.s_M']:+.4f} m off)")
    y = first.copy()
    y[k] = truth["trigger.s_M"]
    r = refine(q, y, max_evals=60, central=True, channel_weights=w, rel_step=STEP)
    print(f"Levenberg-Marquardt from the first seed's point, s_M at the truth: S per sample "
          f"{S(y):.3f} -> {r.f / q.samples.size:.3f} (s_M {r.x[k] - truth['trigger.s_M']:+.4f} m off)")
    p.sim.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
