#!/usr/bin/env python3
"""What the FMU's forward sensitivities cost against the differences they
replace: per layout, a start-stop run from rest (relaxation, then the
protocol's set point for SECONDS) alone, the same run with a follower for
each of the nine design variables the core can differentiate
(fmu_src/sensitivity.c), and the eighteen runs of central differences of
those nine, as an identification runs them (the base's relaxed chain kept:
a step of a CoR or a gain restores it, one of the pretension or the
chain's position relaxes again). CPU-s of each in one process, one after the other, so the ratios
hold on a noisy machine; the per-follower cost is (with - alone) / 9 in runs
of its own.

    .venv/bin/python benchmarks/bench_sensitivities.py --json benchmarks/results/sensitivities.json
    .venv/bin/python benchmarks/bench_sensitivities.py --doc --json benchmarks/results/sensitivities.json
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
from lss_fmu.variables import FORCE_CHANNELS, sensitivity_output, value_reference  # noqa: E402

LAYOUTS = ("layout7", "layout1", "layout3")
SECONDS = 1.0
H = 1.0 / 600
# the design variables the core differentiates on a record from rest, at a point inside their bounds,
# with the identification's step (EXACT_STEP of a typical range) and a central step of 2 % of it
VARIABLES = {"contact.e_JA": (0.5, 0.7), "contact.e_JR": (0.5, 0.7), "contact.e_SW": (0.5, 0.7),
             "contact.e_RW": (0.5, 0.7), "chain.pretension": (None, 0.004), "wheel.mu_roll": (0.004, 0.008),
             "chain.s_start": (10.0, 2.0), "drive.Kp": (2000.0, 2000.0), "drive.Ki": (500.0, 1000.0)}


def params(layout: str) -> tuple:
    track = float(load_track(layout).length)
    proto = Protocol("start-stop", ramp_time=0.1, step_time=0.6)   # up, then down within the second simulated
    p = {"layout.name": layout, "contact.model": 2, "chain.v_init": 0.0, "chain.transducer": 0,
         "drive.v_ref": 0.0, "chain.relax_time": proto.relax_time(track)}
    for name, (value, _) in VARIABLES.items():
        if value is not None:
            p[name] = value
    return p, proto.schedule(1.5, 1.5)


def run(sim: ChainSimulator, p: dict, speed, channels) -> tuple:
    c = time.process_time()
    rows = []
    for t, v in sim.stream(H, channels, p, TRANSIENT_TOLERANCE, inputs={"drive.v_ref": speed}):
        rows.append(v.copy())
        if t >= SECONDS - 1e-12:
            break
    return time.process_time() - c, np.array(rows)


def measure(layout: str) -> dict:
    base, speed = params(layout)
    with ChainSimulator() as sim:   # the pretension the layout is built with
        sim.start({"layout.name": layout})
        d = float(sim.get("chain.pretension"))
    base["chain.pretension"] = d
    with ChainSimulator() as sim:
        alone, y0 = run(sim, base, speed, FORCE_CHANNELS)
    sp = dict(base, **{"sensitivity.n": len(VARIABLES)})
    channels = list(FORCE_CHANNELS)
    for k, (name, (_, span)) in enumerate(VARIABLES.items(), 1):
        sp[f"sensitivity.p{k}.vr"] = value_reference(name)
        sp[f"sensitivity.p{k}.step"] = 1e-6 * (span if name != "chain.pretension" else d)
        channels += [sensitivity_output(k, c) for c in FORCE_CHANNELS]
    with ChainSimulator() as sim:
        followed, y = run(sim, sp, speed, channels)
    central = 0.0
    with ChainSimulator() as sim:
        # as in an identification: the base's relaxed chain is kept, and a step of a variable the
        # relaxation ignores (a CoR, a gain) restores it instead of relaxing again (lss_fmu.runner)
        run(sim, base, speed, FORCE_CHANNELS)
        for name, (_, span) in VARIABLES.items():
            h = 0.02 * (span if name != "chain.pretension" else d)
            for sign in (1, -1):
                cpu, _ = run(sim, dict(base, **{name: base[name] + sign * h}), speed, FORCE_CHANNELS)
                central += cpu
    n = len(VARIABLES)
    return {"layout": layout, "track_m": float(load_track(layout).length), "seconds": SECONDS,
            "relax_s": base["chain.relax_time"], "alone_cpu_s": alone, "followed_cpu_s": followed,
            "central_cpu_s": central, "per_follower_runs": (followed - alone) / n / alone,
            "jacobian_ratio": followed / (central + alone), "same_leader": bool(np.array_equal(y[:, :7], y0))}


def table(rows: list) -> str:
    out = ["| layout | track, m | a run from rest (relaxation + 1 s), CPU-s | with 9 followers, CPU-s | "
           "a follower, in runs of its own | 18 runs of central differences, CPU-s | "
           "the Jacobian with its base run, followers / central | the leader bit for bit the run alone |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['layout']} | {r['track_m']:.0f} | {r['alone_cpu_s']:.2f} | {r['followed_cpu_s']:.2f} | "
                   f"{r['per_follower_runs']:.2f} | {r['central_cpu_s']:.2f} | {r['jacobian_ratio']:.2f} | "
                   f"{'yes' if r['same_leader'] else 'no'} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--layouts", default=",".join(LAYOUTS))
    ap.add_argument("--json", default=None)
    ap.add_argument("--doc", action="store_true", help="write the table of --json into docs/benchmarks.md")
    args = ap.parse_args(argv)
    if args.doc:
        write_between(ROOT / "docs" / "benchmarks.md", "sensitivities",
                      table(json.loads(Path(args.json).read_text())["rows"]))
        return 0
    rows = []
    for layout in args.layouts.split(","):
        rows.append(measure(layout))
        print(table(rows[-1:]).splitlines()[-1], file=sys.stderr)
        if args.json:
            write_json_atomic(args.json, {"command": " ".join(sys.argv), "machine": machine(), "rows": rows})
    print(table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
