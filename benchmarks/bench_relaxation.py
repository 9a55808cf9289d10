#!/usr/bin/env python3
"""What a start from rest costs and how settled it is: the chain's relaxation
at rest (chain.relax_time, fmu_src/chain_relax.c) per layout.

For each layout the chain at rest is relaxed for its protocol relax time T
(lss_fmu.protocol.Protocol.relax_time) at three places on its track (10 m,
0.37 and 0.71 of its length) and then left at rest, the drive holding it, for
DRIFT_S: the CPU of the start, and the largest change of the transducer's
seven forces over that time (a settled chain does not move). Then whether
the start is a smooth function of where the chain stands: the forces at
t = 0 for trigger points SMOOTH_STEP apart, their largest second difference
against their largest first difference. Then the relaxation of length T at
two looser run tolerances (the relaxation runs at the run's, at most 1e-5;
before, at ten times the run's, at most 1e-3): what a looser run saves.

    .venv/bin/python benchmarks/bench_relaxation.py --json benchmarks/results/relaxation.json
    .venv/bin/python benchmarks/bench_relaxation.py --doc --json benchmarks/results/relaxation_kinetic.json \
        benchmarks/results/relaxation_intervals.json benchmarks/results/relaxation.json

`--label` names the relaxation the FMU was built with (a row label of the
table); the kinetic-damping file was measured on the build before the
viscous relaxation, the fixed-schedule file (damping applied between 1 ms
intervals) with `--fmu` on the build before the damping went into the
equations of motion.
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

LAYOUTS = ("layout1", "layout2", "layout3", "layout4", "layout5", "layout6", "layout7")
PLACES = (None, 0.37, 0.71)        # where the chain stands: 10 m, then these shares of the track
DRIFT_S = 0.5                      # s left at rest after the start
SMOOTH_STEP = 5e-4                 # m between the trigger points of the smoothness scan (17 points)


def start(sim: ChainSimulator, layout: str, relax: float, tolerance: float, s_start: float) -> tuple:
    """(CPU-s of the start, the transducer's forces after it)."""
    c = time.process_time()
    sim.start({"layout.name": layout, "chain.v_init": 0.0, "chain.relax_time": relax, "chain.s_start": s_start,
               "drive.v_ref": 0.0}, tolerance=tolerance)
    return time.process_time() - c, np.array([sim.get(n) for n in FORCE_CHANNELS])


def drift(sim: ChainSimulator) -> float:
    """The largest change of a transducer force, N, while the chain stays at rest for DRIFT_S."""
    F0, worst = np.array([sim.get(n) for n in FORCE_CHANNELS]), 0.0
    for _ in range(int(round(DRIFT_S * 300))):
        sim.step(1.0 / 300.0)
        worst = max(worst, float(np.max(np.abs(np.array([sim.get(n) for n in FORCE_CHANNELS]) - F0))))
    return worst


def measure(layout: str, fmu=None) -> dict:
    track = load_track(layout)
    L = float(track.length)
    T = Protocol(name="start-stop").relax_time(L)
    with ChainSimulator(fmu) as sim:
        start(sim, layout, T, TRANSIENT_TOLERANCE, 5.0)   # untimed: the first start also reads the layout
        places = []
        for share in PLACES:
            s = 10.0 if share is None else share * L
            c, _ = start(sim, layout, T, TRANSIENT_TOLERANCE, s)
            places.append({"s_start": s, "cpu_s": c, "drift_N": drift(sim)})
        F = np.array([start(sim, layout, T, TRANSIENT_TOLERANCE, 10.0 + k * SMOOTH_STEP)[1] for k in range(17)])
        tol = {t: start(sim, layout, T, t, 10.0)[0] for t in (1e-4, 1e-3)}
    d1, d2 = np.abs(np.diff(F, axis=0)).max(), np.abs(np.diff(F, 2, axis=0)).max()
    return {"layout": layout, "carts": int(track.n_carts), "length_m": L, "relax_s": T, "places": places,
            "smooth": {"step_m": SMOOTH_STEP, "first_difference_N": float(d1), "second_difference_N": float(d2)},
            "cpu_by_tolerance": {f"{t:g}": v for t, v in tol.items()}}


def table(files: list) -> str:
    data = files[0]
    lines = [f"| relaxation | layout | track, m | T, s | CPU-s of a start at T (run tolerance {data['tolerance']:g}) "
             f"| drift at rest over {DRIFT_S:g} s after it, N (3 places) "
             f"| forces at t = 0, {SMOOTH_STEP * 1e3:g} mm apart: largest 1st / 2nd difference, N "
             "| CPU-s at T, run tolerance 1e-4 / 1e-3 |", "|---|---|---|---|---|---|---|---|"]
    for r, label in [(r, d.get("label", "")) for d in files for r in d["rows"]]:
        cpu = np.mean([p["cpu_s"] for p in r["places"]])
        lines.append(f"| {label} | {r['layout']} | {r['length_m']:.0f} | {r['relax_s']:.2f} | {cpu:.2f} | "
                     + ", ".join(f"{p['drift_N']:.1f}" for p in r["places"])
                     + f" | {r['smooth']['first_difference_N']:.3f} / {r['smooth']['second_difference_N']:.3f}"
                     + f" | {r['cpu_by_tolerance']['0.0001']:.2f} / {r['cpu_by_tolerance']['0.001']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layouts", default=",".join(LAYOUTS))
    ap.add_argument("--json", nargs="+", default=None, help="the result file (with --doc: one or more)")
    ap.add_argument("--label", default="viscous, in the equations", help="the relaxation the FMU was built with")
    ap.add_argument("--fmu", default=None, help="the FMU to measure (default: the project's build)")
    ap.add_argument("--doc", action="store_true", help="write the table of --json into docs/benchmarks.md and stop")
    args = ap.parse_args(argv)
    if args.doc:
        if not args.json:
            raise SystemExit("--doc needs --json FILE")
        write_between(ROOT / "docs" / "benchmarks.md", "relaxation",
                      table([json.loads(Path(f).read_text()) for f in args.json]))
        return 0
    rows = []
    for layout in args.layouts.split(","):
        rows.append(measure(layout.strip(), args.fmu))
        print(f"{layout}: drift {[round(p['drift_N'], 1) for p in rows[-1]['places']]} N after "
              f"T = {rows[-1]['relax_s']:.2f} s", file=sys.stderr)
    data = {"command": " ".join(sys.argv), "machine": machine(), "tolerance": TRANSIENT_TOLERANCE,
            "label": args.label, "rows": rows}
    if args.json:
        write_json_atomic(args.json[0], data)
    print(table([data]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
