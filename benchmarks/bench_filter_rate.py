#!/usr/bin/env python3
"""The logger's anti-alias filter at its declared rate against the communication grid's.

The virtual transducer cart filters the forces at its internal rate (1200 Hz,
meta.json sensor.internal_rate_Hz) before it samples them at 300 Hz; until
commit f9a0df0 the identification ran the same Butterworth on its
communication grid (600 Hz). This benchmark identifies the four CoRs of
single start-stop records (the drive's variables at their true values, the
likelihood objective, 2 s) both ways and keeps f / f(truth), each CoR's error
and its interval's standard deviation (docs/identification.md, "The logger's
filter at its own rate").

    .venv/bin/python benchmarks/bench_filter_rate.py [--measurements 13,18,4,17] [--repeats 3]
    .venv/bin/python benchmarks/bench_filter_rate.py --table

Each identification is written to benchmarks/results/filter_rate_ab.json as
soon as it is done; a stopped run resumes there. One process, one core.
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
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from identification.pipeline.identify import identify  # noqa: E402
from identification.objective.problem import drive_known, from_measurement  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import generate_set, load_truth, parse_numbers, true_design_values  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "filter_rate_ab.json"
WORK = ROOT / "build" / "bench_filter_rate"
SHOWN = ("contact.e_JA", "contact.e_SW", "contact.e_RW")
AT_TRUTH = 1.02   # f / f(truth) up to which a fit counts as at the noise


def one(meas_dir: Path, variant: str, window: float, evals: int, refine: int) -> dict:
    m = load_measurement(meas_dir)
    truth = true_design_values(load_truth(m))
    p = drive_known(from_measurement(m, "LW", window=window, tare=True, objective="likelihood"), truth)
    if variant == "grid":
        p = dataclasses.replace(p, filter_rate=None)
    c0 = time.process_time()
    try:
        f_truth = p(np.array([truth[n] for n in CORS]))
        res = identify(p, max_evals=evals, refine_evals=refine, uncertainty=True, seed=0, progress=False)
    finally:
        p.sim.close()
    return {"f_truth": f_truth, "f": res.f, "err": {n: float(x - truth[n]) for n, x in zip(CORS, res.x)},
            "sd": {iv.name: iv.sd for iv in res.intervals}, "cpu_s": time.process_time() - c0}


def table(rows: list) -> str:
    out = ["| record | filter at | f / f(truth) | e_JA err (sd) | e_SW err (sd) | e_RW err (sd) | CPU s |",
           "|---|---|---|---|---|---|---|"]
    tally = {v: [0, 0, 0, 0] for v in ("grid", "rate")}
    for r in rows:
        q = r["f"] / r["f_truth"]
        cells = " | ".join(f"{r['err'][n]:+.3f} ({r['sd'][n]:.4f})" for n in SHOWN)
        where = "the logger's rate" if r["variant"] == "rate" else "the grid"
        out.append(f"| {r['record']} | {where} | {q:.3f} | {cells} | {r['cpu_s']:.0f} |")
        if q <= AT_TRUTH:
            t = tally[r["variant"]]
            t[0] += 1
            t[1] += sum(abs(r["err"][n]) <= 0.03 for n in SHOWN)
            t[2] += sum(abs(r["err"][n]) <= 1.96 * r["sd"][n] for n in SHOWN)
            t[3] += all(abs(r["err"][n]) <= 0.03 for n in SHOWN)
    for v, (n, within, cover, all3) in tally.items():
        out.append(f"\n{v}: {n} fits at f <= {AT_TRUTH} f(truth); of their {3 * n} CoRs {within} within 0.03, "
                   f"{cover} inside their 95 % interval; all three within 0.03 on {all3}")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--measurements", default="13,18,4,17")
    ap.add_argument("--repeats", type=int, default=3, help="start-stops per measurement (the chain parked elsewhere)")
    ap.add_argument("--window", type=float, default=2.0)
    ap.add_argument("--max-evals", type=int, default=120)
    ap.add_argument("--refine-evals", type=int, default=40)
    ap.add_argument("--table", action="store_true", help="print the table of the results so far")
    args = ap.parse_args(argv)
    rows = json.loads(RESULTS.read_text()) if RESULTS.exists() else []
    if args.table:
        print(table(rows))
        return 0
    numbers = parse_numbers(args.measurements)
    for k in range(args.repeats):
        generate_set("recovery", WORK / ("data" if k == 0 else f"data_r{k}"), numbers, workers=1,
                     protocol="start-stop", progress=False, repeat=k)
    done = {(r["record"], r["variant"]) for r in rows}
    for k in range(args.repeats):
        for n in numbers:
            record = f"r{k}/m{n:02d}"
            for variant in ("rate", "grid"):
                if (record, variant) in done:
                    continue
                folder = WORK / ("data" if k == 0 else f"data_r{k}") / f"m{n:02d}"
                rows.append({"record": record, "variant": variant,
                             **one(folder, variant, args.window, args.max_evals, args.refine_evals)})
                write_json_atomic(RESULTS, rows)
                print(table(rows[-1:]).splitlines()[2], flush=True)
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
