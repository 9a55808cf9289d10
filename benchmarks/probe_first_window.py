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
  truth (whether s_M alone is what the complex misses).

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

from identification.base_polish import STEP  # noqa: E402
from identification.growing import FIRST  # noqa: E402
from identification.identify import identify  # noqa: E402
from identification.problem import from_measurement, tared  # noqa: E402
from identification.refine import refine  # noqa: E402
from identification.windowing import truncated  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import load_truth, true_design_values  # noqa: E402

SHIFTS = (-0.03, -0.01, -0.005, 0.0, 0.005, 0.01, 0.03)   # m, s_M moved from the truth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("record", help="a recovery record, e.g. m21")
    ap.add_argument("--data", default="build/bench_recovery/start-stop/data")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--evals", type=int, default=300)
    ap.add_argument("--window", type=float, default=2.5)
    args = ap.parse_args(argv)
    m = load_measurement(Path(args.data) / args.record)
    p = from_measurement(m, "LW", window=args.window, tare=True, objective="likelihood")
    q = truncated(p, p.times[0] + FIRST)
    w = 1.0 / np.asarray(p.noise, float) ** 2

    def S(x) -> float:
        return float(np.sum(tared(q.samples - q.simulate(x), q.tare) ** 2 * w)) / q.samples.size

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
    y = first.copy()
    y[k] = truth["trigger.s_M"]
    r = refine(q, y, max_evals=60, central=True, channel_weights=w, rel_step=STEP)
    print(f"Levenberg-Marquardt from the first seed's point, s_M at the truth: S per sample "
          f"{S(y):.3f} -> {r.f / q.samples.size:.3f} (s_M {r.x[k] - truth['trigger.s_M']:+.4f} m off)")
    p.sim.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
