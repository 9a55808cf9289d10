#!/usr/bin/env python3
"""The rest fit on its own: how often it puts a trigger point in the wrong valley.

For each rig seed and measurement, three start-stop records are made (`lss
rig --protocol start-stop --repeat K`, records of `--seconds`), the joint
problem of the front door is cut to its first window (0.3 s), and
`identification.pipeline.rest_fit.fit_rest` fits the pretension and every
record's trigger point from their nominal values and marks, the CoRs at
their start values, exactly as the grown identification's first stage does.
The answer files are read only to score: the pretension's relative error and
each trigger point's error in m; a sorter counts as missed where a trigger
point ends more than `--valley` m off (the valleys along it are about 0.1 m
wide).

    .venv/bin/python benchmarks/bench_rest_fit.py --json benchmarks/results/rest_fit.json

Records are kept under --work and made once.
"""
from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench_common import hash_sources  # noqa: E402
from bench_recovery import set_fmu  # noqa: E402
from identification.objective.joint import own  # noqa: E402
from identification.pipeline.driver import build_problem  # noqa: E402
from identification.pipeline.growing import FIRST, at_rest, STEP_ITERATIONS  # noqa: E402
from identification.pipeline.rest_fit import fit_rest  # noqa: E402
from identification.pipeline.settings import Settings  # noqa: E402
from identification.pipeline.windowing import truncated  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import TRIGGER  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import (DEFAULT_SEED, folder_name, generate_set, load_truth, parse_numbers,  # noqa: E402
                         true_design_values)

REPEATS = 3


def row(dirs, number: int) -> dict:
    """The rest fit on one sorter's three records, scored against their answers."""
    records = [load_measurement(d / folder_name(number)) for d in dirs]
    problem = build_problem(records, "LW", Settings())
    truth = [true_design_values(load_truth(r)) for r in records]
    q = truncated(problem, problem.times[0] + FIRST)
    w = 1.0 / np.asarray(problem.noise, float) ** 2
    t0 = time.process_time()
    vals, used = fit_rest(q, at_rest(q), w, STEP_ITERATIONS * (2 * len(problem.free) + 2) + 1)
    p_true = truth[0]["chain.pretension"]
    return {"number": number, "layout": records[0].layout_for_fmu,
            "pretension_rel_error": vals["chain.pretension"] / p_true - 1.0,
            "trigger_errors_m": [vals[own(k)] - truth[k][TRIGGER] for k in range(len(records))],
            "simulations": int(used), "cpu_s": time.process_time() - t0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rig-seeds", default=f"{DEFAULT_SEED},7,11")
    ap.add_argument("--measurements", default="1-8,12-22", help="default: all but layout 3's (685 carts)")
    ap.add_argument("--seconds", type=float, default=1.2, help="record length, s (only the first 0.3 s is fitted)")
    ap.add_argument("--valley", type=float, default=0.1, help="a trigger point this far off, m, counts as missed")
    ap.add_argument("--work", default="build/bench_rest_fit")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    numbers = parse_numbers(args.measurements)
    out = {"command": " ".join(sys.argv), "code": hash_sources(hashlib.sha256()).hexdigest()[:12],
           "valley_m": args.valley, "seeds": {}}
    for seed in (int(s) for s in args.rig_seeds.split(",")):
        dirs = [Path(args.work) / f"s{seed}" / ("data" if k == 0 else f"data_r{k}") for k in range(REPEATS)]
        fmu = set_fmu(dirs[0])   # the FMU that made the records already there
        for k, d in enumerate(dirs):
            generate_set("recovery", d, numbers, seed=seed, workers=1, lap_seconds=args.seconds, progress=False,
                         protocol="start-stop", repeat=k, log=lambda msg: None, fmu=fmu)
        rows = []
        for n in numbers:
            rows.append(row(dirs, n))
            r = rows[-1]
            print(f"seed {seed} m{n:02d} {r['layout']}: pretension {100 * r['pretension_rel_error']:+.2f} %, trigger "
                  f"points {', '.join(f'{e:+.3f}' for e in r['trigger_errors_m'])} m, {r['simulations']} simulations",
                  flush=True)
        missed = [r["number"] for r in rows if max(abs(e) for e in r["trigger_errors_m"]) > args.valley]
        out["seeds"][str(seed)] = {"rows": rows, "missed": missed, "n": len(rows),
                                   "simulations": int(sum(r["simulations"] for r in rows))}
        print(f"seed {seed}: {len(missed)} of {len(rows)} with a trigger point more than {args.valley} m off "
              f"({', '.join(f'm{m:02d}' for m in missed) or 'none'})", flush=True)
        if args.json:
            write_json_atomic(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
