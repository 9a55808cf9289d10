#!/usr/bin/env python3
"""How rough the CoR columns of a recovery measurement's Jacobian are at its
true values, per solver tolerance: |forward - backward| / |their mean| in the
likelihood's metric, measured again at half the step where it is at least
uncertainty.ROUGH (the intervals' own test, `jacobian(recheck=...)`), on the
measurement's records identified jointly. A column at or above ROUGH after the
recheck is one the intervals would not claim.

    .venv/bin/python benchmarks/probe_roughness.py --measurement 9 --records 3 --tolerances 1e-4,5e-4,1e-3
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

from profile_identification import records_of  # noqa: E402
from identification import Settings  # noqa: E402
from identification.objective.jacobian import jacobian  # noqa: E402
from identification.objective.uncertainty import ROUGH  # noqa: E402
from identification.pipeline.driver import build_problem  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS, symbol  # noqa: E402
from lss_fmu.rig import load_truth, true_design_values  # noqa: E402


def at_tolerance(p, tol: float):
    """The problem (or each record of a joint one) at solver tolerance tol, sharing its simulator."""
    if hasattr(p, "parts"):
        parts = []
        for a in p.parts:
            b = dataclasses.replace(a, tolerance=tol)
            b.sim = a.sim
            parts.append(b)
        return dataclasses.replace(p, parts=parts)
    q = dataclasses.replace(p, tolerance=tol)
    q.sim = p.sim
    return q


def weights_of(p) -> np.ndarray:
    parts = getattr(p, "parts", [p])
    return np.concatenate([1.0 / np.asarray(a.noise, float) ** 2 for a in parts])


def measure(number: int, records: int, tolerances, work: Path) -> dict:
    rec = records_of(work, number, records)
    p = build_problem(rec, "LW", Settings())
    truths = [true_design_values(load_truth(Path(r.path))) for r in rec]

    def true_value(name: str) -> float:   # a joint problem's own trigger point of record k is "name@k"
        base, _, k = name.partition("@")
        return truths[int(k) if k else 0][base]

    x = np.array([true_value(n) for n in p.free])
    only = [p.free.index(c) for c in CORS]
    w = weights_of(p)
    rows = []
    for tol in tolerances:
        q = at_tolerance(p, tol)
        c = time.process_time()
        _, steps, rough = jacobian(q, x, q.simulate(x), weights=w, recheck=ROUGH, only=only)
        rows.append({"tol": tol, "cpu_s": time.process_time() - c,
                     "rough": {symbol(p.free[k]): float(rough[k]) for k in only},
                     "step": {symbol(p.free[k]): float(steps[k]) for k in only}})
        print(f"m{number:02d} ({rec[0].layout}), {records} record(s), tolerance {tol:g}: "
              + ", ".join(f"{s} {r:.2f}" for s, r in rows[-1]["rough"].items()), flush=True)
    return {"measurement": number, "layout": rec[0].layout, "records": records, "rough_limit": ROUGH, "rows": rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--measurement", type=int, default=9)
    ap.add_argument("--records", type=int, default=3)
    ap.add_argument("--tolerances", default="1e-4,5e-4,1e-3", help="comma-separated solver tolerances")
    ap.add_argument("--work", default="build/bench_recovery")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    try:
        tolerances = [float(t) for t in args.tolerances.split(",")]
    except ValueError as e:
        ap.error(f"--tolerances {args.tolerances!r}: {e}")
    entry = {"command": " ".join(sys.argv), **measure(args.measurement, args.records, tolerances, Path(args.work))}
    if args.json:
        write_json_atomic(args.json, entry)
    else:
        print(json.dumps(entry, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
