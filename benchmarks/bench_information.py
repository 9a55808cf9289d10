#!/usr/bin/env python3
"""What a record can tell about the CoRs at all: the Cramér-Rao bound (issue 17).

For a recovery measurement written by the rig with a given protocol, the
simulated forces are linearised at the TRUE design values, J = d sim / d x
by central differences through the FMU, and weighted by the sensor's
declared white noise (lss_fmu.sensor.NOISE_STD). The covariance
(J' W J)^-1 is the smallest any unbiased estimator can reach from that
record: if its standard deviation of a CoR is not well below 0.01, no
optimiser will find that CoR within 0.03, whatever its budget. Reported
per protocol and layout, with the ten design variables free and with the
four CoRs alone (drive, pretension, trigger known), together with how
smooth the record is in each variable (forward against backward
difference: a chaotic record has no meaningful derivative).

    .venv/bin/python benchmarks/bench_information.py --protocols start-up,start-stop \\
        --measurements 1-22 --window 2.5 --json benchmarks/results/information.json

Each case is written to the JSON as it finishes (atomically); a rerun skips
the cases already there. `--report` summarises the JSON (a Markdown table, the
figure, and the share of records expected within 0.03 with k records of the
kind, the standard deviations falling as 1 / sqrt(k)).

    .venv/bin/python benchmarks/bench_information.py --report --figure docs/figures/information.png
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from identification.objective.problem import from_measurement  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS, SYMBOL  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import load_truth, parse_numbers, run_measurement, true_design_values  # noqa: E402
from lss_fmu.runner import ChainSimulator  # noqa: E402
from lss_fmu.sensor import NOISE_STD  # noqa: E402
from lss_fmu.variables import FORCE_CHANNELS  # noqa: E402

STEP = 0.01      # difference step, of each variable's bound range
ROUGH = 0.5      # |forward - backward| / |central| (in the noise metric) beyond which a variable is not smooth


def information(p, x: np.ndarray, sigma: np.ndarray):
    """J (noise-weighted, flattened), and per variable the roughness of the record
    in it: objective.jacobian.jacobian with a fixed step of STEP of each bound range."""
    from identification.objective.jacobian import jacobian
    lo, hi = np.array(p.bounds_array, float).T
    J, _, rough = jacobian(p, x, p.simulate(x), weights=1.0 / sigma ** 2, steps=STEP * (hi - lo))
    J = J / sigma[None, :, None]
    return J.reshape(-1, J.shape[2]), rough


def bound_sd(J: np.ndarray, idx) -> np.ndarray:
    """Standard deviations of the variables `idx` with only those free."""
    Jk = J[:, idx]
    cov = np.linalg.pinv(Jk.T @ Jk)
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def case(protocol: str, number: int, window: float, work: Path, sim) -> dict:
    data = work / f"{protocol}_{window:g}s"
    folder = data / f"m{number:02d}"
    if not folder.exists():
        run_measurement("recovery", number, data, sim, protocol=protocol, lap_seconds=window + 0.2)
    meas = load_measurement(folder)
    truth = true_design_values(load_truth(meas))
    p = from_measurement(meas, "LW", window=window, tare=True)
    x = np.array([truth[n] for n in p.free])
    sigma = np.array([NOISE_STD[c] for c in FORCE_CHANNELS])
    c0 = time.process_time()
    try:
        J, rough = information(p, x, sigma)
    finally:
        p.sim.close()
    free = list(p.free)
    cors = [free.index(n) for n in CORS]
    sd_all = bound_sd(J, list(range(len(free))))
    sd_cors = bound_sd(J, cors)
    return {"protocol": protocol, "measurement": number, "layout": meas.meta.get("layout"),
            "window_s": window, "protocol_meta": p.protocol.to_meta(), "n_samples": int(len(p.times)),
            "sd_ten_free": {SYMBOL[n]: float(sd_all[free.index(n)]) for n in free},
            "sd_cors_only": {SYMBOL[n]: float(s) for n, s in zip(CORS, sd_cors)},
            "roughness": {SYMBOL[n]: float(r) for n, r in zip(free, rough)},
            "cpu_s": time.process_time() - c0}


CORS3 = ("e_JA", "e_SW", "e_RW")
TOL = 0.03


def smooth(c: dict, k: str) -> bool:
    return c["roughness"][k] <= ROUGH   # NaN (one-sided at a bound) counts as rough


def expected_within(cases: list, k_records: int) -> tuple:
    """(records smooth in e_JA, e_SW and e_RW; expected number of them with all
    three within TOL, the estimate normal with the bound's sd / sqrt(k))."""
    n, exp = 0, 0.0
    for c in cases:
        if not all(smooth(c, k) for k in CORS3):
            continue
        n += 1
        p = 1.0
        for k in CORS3:
            sd = c["sd_ten_free"][k] / math.sqrt(k_records)
            p *= math.erf(TOL / (sd * math.sqrt(2.0)))
        exp += p
    return n, exp


def report(path: Path, figure) -> None:
    cases = json.loads(path.read_text())["cases"]
    protos = sorted({(c["protocol"], c["window_s"]) for c in cases}, key=lambda q: (-len(
        [c for c in cases if (c["protocol"], c["window_s"]) == q]), q))
    print("| protocol | window | records | CoR | smooth | median sd (smooth) | sd <= 0.015 and smooth |")
    print("|---|---|---|---|---|---|---|")
    for proto, w in protos:
        cs = [c for c in cases if c["protocol"] == proto and c["window_s"] == w]
        for k in CORS3 + ("e_JR",):
            sm = [c["sd_ten_free"][k] for c in cs if smooth(c, k)]
            med = f"{np.median(sm):.4f}" if sm else "-"
            ok = sum(1 for c in cs if smooth(c, k) and c["sd_ten_free"][k] <= TOL / 2)
            print(f"| {proto} | {w:g} s | {len(cs)} | {k} | {len(sm)} | {med} | {ok} |")
    print("\nexpected number of records with e_JA, e_SW and e_RW all within 0.03, with k records of the kind:")
    for proto, w in protos:
        cs = [c for c in cases if c["protocol"] == proto and c["window_s"] == w]
        row = [expected_within(cs, k) for k in (1, 2, 4, 8)]
        print(f"  {proto} {w:g} s ({len(cs)} records, {row[0][0]} smooth in all three): " +
              ", ".join(f"k={k}: {e:.1f}" for k, (_, e) in zip((1, 2, 4, 8), row)))
    if figure:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        from lss_app.figures.save import save_figure
        main_protos = [q for q in protos if len([c for c in cases if (c["protocol"], c["window_s"]) == q]) > 5]
        fig, axes = plt.subplots(1, 3, figsize=(13, 4), sharey=True)
        for ax, k in zip(axes, CORS3):
            for i, (proto, w) in enumerate(main_protos):
                cs = sorted([c for c in cases if (c["protocol"], c["window_s"]) == (proto, w)],
                            key=lambda c: c["measurement"])
                xs = np.array([c["measurement"] for c in cs]) + (i - 0.5) * 0.3
                sd = np.array([c["sd_ten_free"][k] for c in cs])
                rough = np.array([not smooth(c, k) for c in cs])
                ax.semilogy(xs[~rough], sd[~rough], "o", color=f"C{i}", label=f"{proto}, {w:g} s")
                ax.semilogy(xs[rough], sd[rough], "x", color=f"C{i}", alpha=0.6,
                            label=f"{proto}: not smooth (no bound)")
            ax.axhline(TOL / 2, color="k", lw=0.8, ls="--")
            ax.set_title(f"{k}: Cramér-Rao sd, ten free")
            ax.set_xlabel("recovery measurement")
            ax.set_xticks(range(1, 23, 3))
        axes[0].set_ylabel("standard deviation (dashed: 0.015, i.e. 2 sd = 0.03)")
        axes[0].legend(fontsize=7)
        fig.tight_layout()
        print("figure:", save_figure(fig, figure))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--protocols", default="start-up,speed-step,stop,steady")
    ap.add_argument("--measurements", default="1,5,9,12,13,19,20")
    ap.add_argument("--window", type=float, default=2.5)
    ap.add_argument("--work", type=Path, default=Path("build/bench_information"))
    ap.add_argument("--json", type=Path, default=Path("benchmarks/results/information.json"))
    ap.add_argument("--report", action="store_true", help="summarise the JSON instead of computing")
    ap.add_argument("--figure", default=None, help="with --report: the figure's path (PNG and SVG)")
    a = ap.parse_args(argv)
    if a.report:
        report(a.json, a.figure)
        return 0
    done = json.loads(a.json.read_text()) if a.json.exists() else {"cases": []}
    have = {(c["protocol"], c["measurement"], c["window_s"]) for c in done["cases"]}
    with ChainSimulator() as sim:
        for proto in a.protocols.split(","):
            for m in parse_numbers(a.measurements):
                if (proto, m, a.window) in have:
                    continue
                r = case(proto, m, a.window, a.work, sim)
                done["cases"].append(r)
                write_json_atomic(a.json, done)
                cors = "  ".join(f"{k} {r['sd_ten_free'][k]:.4f}/{r['sd_cors_only'][k]:.4f}"
                                 f"{'~' if not r['roughness'][k] <= ROUGH else ''}" for k in r["sd_cors_only"])
                print(f"{proto:10s} m{m:02d} layout {r['layout']}: sd ten free / CoRs only: {cors}"
                      f"  ({r['cpu_s']:.0f} CPU-s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
