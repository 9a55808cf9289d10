#!/usr/bin/env python3
"""What a start from rest costs and how settled it is: the chain's relaxation
at rest (chain.relax_time, fmu_src/chain_relax.c) per layout.

For each layout the chain at rest (trigger point 10 m) is relaxed for k times
its protocol relax time T (lss_fmu.protocol.Protocol.relax_time) and the
transducer's seven forces read at the end: the CPU of the start, and the
largest change of a force against the longest relaxation (how far the
relaxation of length T is from settled). Then the relaxation of length T at
two run tolerances (the relaxation runs at ten times the run's, at most
1e-3): whether its steps are bounded by the tolerance.

    .venv/bin/python benchmarks/bench_relaxation.py --json benchmarks/results/relaxation.json
    .venv/bin/python benchmarks/bench_relaxation.py --doc --json benchmarks/results/relaxation.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_common import ROOT, machine, write_between  # noqa: E402  (sets one BLAS thread)

import numpy as np  # noqa: E402

from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.layouts import load_track  # noqa: E402
from lss_fmu.protocol import TRANSIENT_TOLERANCE, Protocol  # noqa: E402
from lss_fmu.runner import ChainSimulator  # noqa: E402
from lss_fmu.variables import FORCE_CHANNELS  # noqa: E402

LAYOUTS = ("layout7", "layout1", "layout3")
FACTORS = (0.5, 1.0, 2.0, 3.5)     # relax times, in units of T (the FMU allows up to 10 s)
S_START = 10.0                     # m: where the chain stands on its track


def start(sim: ChainSimulator, layout: str, relax: float, tolerance: float) -> tuple:
    """(CPU-s of the start, the transducer's forces after it)."""
    c = time.process_time()
    sim.start({"layout.name": layout, "chain.v_init": 0.0, "chain.relax_time": relax, "chain.s_start": S_START,
               "drive.v_ref": 0.0}, tolerance=tolerance)
    return time.process_time() - c, np.array([sim.get(n) for n in FORCE_CHANNELS])


def measure(layout: str) -> dict:
    track = load_track(layout)
    T = Protocol(name="start-stop").relax_time(float(track.length))
    with ChainSimulator() as sim:
        runs = {k: start(sim, layout, min(k * T, 10.0), TRANSIENT_TOLERANCE) for k in FACTORS}
        ref = runs[FACTORS[-1]][1]
        tol = {t: start(sim, layout, T, t)[0] for t in (1e-4, 1e-3)}
    return {"layout": layout, "carts": int(track.n_carts),
            "length_m": float(track.length), "relax_s": T,
            "runs": [{"factor": k, "relax_s": min(k * T, 10.0), "cpu_s": cpu,
                      "max_force_change_N": float(np.max(np.abs(F - ref)))} for k, (cpu, F) in runs.items()],
            "cpu_by_tolerance": {f"{t:g}": v for t, v in tol.items()}}


def table(data: dict) -> str:
    lines = [f"| layout | track, m | T, s | CPU-s of a start at T (run tolerance {data['tolerance']:g}) "
             f"| largest force change against {FACTORS[-1]:g} T, N: " + ", ".join(f"{k:g} T" for k in FACTORS[:-1])
             + " | CPU-s at T, run tolerance 1e-4 / 1e-3 (the relaxation at 1e-3) |", "|---|---|---|---|---|---|"]
    for r in data["rows"]:
        at = {x["factor"]: x for x in r["runs"]}
        lines.append(f"| {r['layout']} | {r['length_m']:.0f} | {r['relax_s']:.2f} | {at[1.0]['cpu_s']:.2f} | "
                     + ", ".join(f"{at[k]['max_force_change_N']:.1f}" for k in FACTORS[:-1])
                     + f" | {r['cpu_by_tolerance']['0.0001']:.2f} / {r['cpu_by_tolerance']['0.001']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layouts", default=",".join(LAYOUTS))
    ap.add_argument("--json", default=None)
    ap.add_argument("--doc", action="store_true", help="write the table of --json into docs/benchmarks.md and stop")
    args = ap.parse_args(argv)
    if args.doc:
        if not args.json:
            raise SystemExit("--doc needs --json FILE")
        write_between(ROOT / "docs" / "benchmarks.md", "relaxation", table(json.loads(Path(args.json).read_text())))
        return 0
    rows = []
    for layout in args.layouts.split(","):
        rows.append(measure(layout.strip()))
        at_T = next(r for r in rows[-1]["runs"] if r["factor"] == 1.0)
        print(f"{layout}: {at_T['cpu_s']:.2f} CPU-s at T = {rows[-1]['relax_s']:.2f} s", file=sys.stderr)
    data = {"command": " ".join(sys.argv), "machine": machine(), "tolerance": TRANSIENT_TOLERANCE, "rows": rows}
    if args.json:
        write_json_atomic(args.json, data)
    print(table(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())
