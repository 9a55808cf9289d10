#!/usr/bin/env python3
"""What a record can tell about an effect the model lacks: the smallest
amplitude the closed loop can confirm, from the information the record
carries (issue 53, item 2).

For one recovery measurement per layout, recorded by the rig with a
protocol, the simulation is linearised at the TRUE design values: the base's
columns (the ten design variables, central differences scaled to the
response, identification.objective.jacobian) and the effect's signature
columns at a small amplitude (motor ripple: the cosine and sine phase at
several pole pitches; out-of-round driving wheels: the left and right cosine
and sine of each lobe order, from the catalogue's four phase-pair probes). A
signature g of unit amplitude, with the base free (projected off the base
columns in the declared noise's metric, every channel's mean taken out as
the tare does), carries the information I = g' W g; the loop's test of an
amplitude a has the noncentrality lambda = a^2 I. The loop confirms only if
the likelihood ratio T passes both the Bonferroni bound over the round's
hypotheses and BIC (identification.loop.evidence: T > q ln N + 2 ln m_e),
so the amplitude found in 90 % of records is

    a_90 = sqrt(lambda_90 / I),  P(chi2_q(lambda_90) > threshold) = 0.9,

q the effect's parameters in the extension (3). Reported per layout,
protocol and window: the median over pitches and phases, and the worst
phase, and the roughest CoR column of the base over the whole window (a
record that is not smooth there, past the onset of chaos, has no meaningful
linearisation: its a_90 is not a bound). An amplitude below a_90 can be
there without the record showing it,
whatever the optimiser; a record kind whose a_90 is far above the effect's
realistic size cannot reveal it.

    .venv/bin/python benchmarks/bench_effect_information.py --json benchmarks/results/effect_information.json
    .venv/bin/python benchmarks/bench_effect_information.py --doc --json benchmarks/results/effect_information.json

Each case is written to the JSON as it finishes (atomically); a rerun skips
the cases already there.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_common import ROOT, write_between  # noqa: E402  (sets one BLAS thread)

import numpy as np  # noqa: E402

from identification.loop import reach  # noqa: E402
from identification.loop.catalogue import MotorRipple, WheelOutOfRound  # noqa: E402
from identification.loop.synthetic import TRUTH, effect_case  # noqa: E402
from identification.objective.jacobian import demean_columns, jacobian  # noqa: E402
from identification.objective.noise import ALPHA  # noqa: E402
from identification.objective.uncertainty import ROUGH  # noqa: E402
from identification.objective.problem import from_measurement  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import folder_name, load_truth, make_case, run_measurement, true_design_values  # noqa: E402
from lss_fmu.runner import ChainSimulator  # noqa: E402
from lss_fmu.sensor import NOISE_STD  # noqa: E402
from lss_fmu.variables import FORCE_CHANNELS  # noqa: E402

ROUND_HYPOTHESES = 500      # the Bonferroni m of a round (about 250 scanned, doubled for the larger of two fits)
Q = 3                       # the effect's parameters in the extension (amplitude, phases or pitch)
PITCHES = (0.05, 0.08, 0.12, 0.18, 0.23)   # m, across the catalogue's band
RIPPLE_PROBE = 5.0          # N: the signature's probe amplitude (linear well beyond it)
OOR_ORDERS = (1, 2, 3)
PHASES = np.linspace(0.0, 2.0 * math.pi, 24, endpoint=False)


def threshold(n_values: int, m_effect: int) -> float:
    """The T the loop needs to confirm: Bonferroni at ALPHA over the round, and BIC."""
    return reach.threshold(n_values, ROUND_HYPOTHESES, m_effect, Q)


def lambda_90(c: float) -> float:
    """The noncentrality at which chi2_Q exceeds c with probability 0.9."""
    return reach.lambda_90(c, Q)


def projector(J: np.ndarray, w: np.ndarray):
    """g -> g projected off the base columns J (n, ch, k) in the metric w per channel, after the tare."""
    every = np.ones(J.shape[1], bool)   # the tare takes every channel's mean out
    A = np.stack([(demean_columns(J[:, :, k], every) * np.sqrt(w)).ravel() for k in range(J.shape[2])], axis=1)
    Q_, _ = np.linalg.qr(A)

    def info(g: np.ndarray) -> float:
        v = (demean_columns(g, every) * np.sqrt(w)).ravel()
        v = v - Q_ @ (Q_.T @ v)
        return float(v @ v)
    return info


def analyse(p, x: np.ndarray, w: np.ndarray, windows) -> dict:
    """Per window: a_90 of the ripple and of each runout order, with the base's free variables free."""
    sim0 = p.simulate(x)
    J, _, rough = jacobian(p, x, sim0, weights=w)

    def column(extra: dict, scale: float) -> np.ndarray:
        return (p.simulate(x, extra) - sim0) / scale

    ripple = {pitch: [column({"effects.motor_ripple.amplitude": RIPPLE_PROBE, "effects.motor_ripple.pitch": pitch,
                              "effects.motor_ripple.phase": phi}, RIPPLE_PROBE) for phi in (0.0, 0.5 * math.pi)]
              for pitch in PITCHES}
    oor = {}
    for k in OOR_ORDERS:
        a = WheelOutOfRound.PROBE / k
        P = [column({"effects.wheel_oor.amplitude": a, "effects.wheel_oor.order": k, "effects.wheel_oor.phase_left": pl,
                     "effects.wheel_oor.phase_right": pr}, a) for pl, pr in WheelOutOfRound.PAIRS]
        lc, rs = 0.5 * (P[2] - P[3]), 0.5 * (P[2] + P[3])   # the probes' phase pairs, solved for each side
        oor[k] = (lc, P[1] - rs, P[0] - lc, rs)              # left cos, left sin, right cos, right sin
    out = {"windows": {}, "rough": dict(zip(p.free, map(float, rough)))}
    for win in windows:
        n = int(np.sum(p.times - p.times[0] <= win + 1e-9))
        cut = slice(0, n)
        info = projector(J[cut], w)
        N = n * sim0.shape[1]
        row = {}
        c = threshold(N, len(MotorRipple.pitches()))
        lam = lambda_90(c)
        a90 = [math.sqrt(lam / max(info(math.cos(phi) * gc[cut] + math.sin(phi) * gs[cut]), 1e-300))
               for gc, gs in ripple.values() for phi in PHASES]
        row["motor_ripple_N"] = {"median": float(np.median(a90)), "worst": float(np.max(a90)),
                                 "best": float(np.min(a90)), "threshold_T": c}
        for k, (lc, ls, rc, rs) in oor.items():
            c = threshold(N, len(OOR_ORDERS))
            lam = lambda_90(c)
            a90 = [math.sqrt(lam / max(info((math.cos(pl) * lc + math.sin(pl) * ls + math.cos(pr) * rc
                                             + math.sin(pr) * rs)[cut]), 1e-300))
                   for pl in PHASES[::3] for pr in PHASES[::3]]
            row[f"wheel_oor_{k}_um"] = {"median": 1e6 * float(np.median(a90)), "worst": 1e6 * float(np.max(a90)),
                                        "best": 1e6 * float(np.min(a90)), "threshold_T": c}
        out["windows"][f"{win:g}"] = row
    return out


def rig_case(number: int, protocol: str, seconds: float, windows, work: Path, sim) -> dict:
    """A recovery measurement recorded with `protocol`, the ten design variables free (as the front door)."""
    t0 = time.process_time()
    data = work / protocol
    folder = data / folder_name(number)
    if not (folder / "meta.json").is_file():
        run_measurement("recovery", number, data, sim, protocol=protocol, lap_seconds=seconds, overwrite=True)
    meas = load_measurement(folder)
    truth = true_design_values(load_truth(folder))
    p = from_measurement(meas, "LW", window=max(windows), tare=True, objective="likelihood")
    x = np.array([truth[n] for n in p.free])
    out = analyse(p, x, 1.0 / np.asarray(p.noise, float) ** 2, windows)
    return {"number": number, "layout": meas.layout, "protocol": protocol, **out,
            "cpu_s": time.process_time() - t0}


def release_case(cart: int) -> dict:
    """The release transient of the rates benchmark (layout 7, 1 s, the four CoRs free, the transducer `cart`)."""
    t0 = time.process_time()
    p, _ = effect_case([], 0, transducer=cart)
    x = np.array([TRUTH[n] for n in p.free])
    w = 1.0 / np.array([NOISE_STD[c] for c in FORCE_CHANNELS]) ** 2
    out = analyse(p, x, w, [float(p.times[-1] - p.times[0])])
    return {"layout": "layout7", "protocol": f"release, cart {cart}", **out, "cpu_s": time.process_time() - t0}


def _num(v: float) -> str:
    """Two significant figures, without an exponent."""
    return f"{float(f'{v:.2g}'):g}" if v < 1e5 else f"{v:.2g}"


def table(data: dict) -> str:
    lines = ["| layout | protocol | window, s | motor ripple, N: median (worst phase) | wheel runout 1 lobe, um | "
             "2 lobes, um | 3 lobes, um | roughest CoR (whole window) |", "|---|---|---|---|---|---|---|---|"]
    for key in sorted(data["cases"], key=lambda k: (data["cases"][k]["layout"], data["cases"][k]["protocol"])):
        cse = data["cases"][key]
        last = max(cse["windows"], key=float)
        rough = max(v for n, v in cse["rough"].items() if n.startswith("contact."))
        for win, r in cse["windows"].items():
            cells = [f"{_num(r['motor_ripple_N']['median'])} ({_num(r['motor_ripple_N']['worst'])})"]
            cells += [f"{_num(r[f'wheel_oor_{k}_um']['median'])} ({_num(r[f'wheel_oor_{k}_um']['worst'])})"
                      for k in OOR_ORDERS]
            cells.append((f"{rough:.2f}" + (" (not smooth)" if rough >= ROUGH else "")) if win == last else "")
            lines.append(f"| {cse['layout']} | {cse['protocol']} | {float(win):.1f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--protocols", default="start-stop,start-up")
    ap.add_argument("--release-carts", default="0,20", help="transducer carts of the release transient compared")
    ap.add_argument("--layouts", default="layout1,layout2,layout3,layout4,layout5,layout6,layout7")
    ap.add_argument("--seconds", type=float, default=2.5, help="record length, s")
    ap.add_argument("--windows", default="1.5,2.5", help="windows of the record analysed, s")
    ap.add_argument("--work", default="build/bench_effect_information")
    ap.add_argument("--json", default=None)
    ap.add_argument("--doc", action="store_true",
                    help="write the table of --json into docs/close_loop.md and stop")
    args = ap.parse_args(argv)
    data = json.loads(Path(args.json).read_text()) if args.json and Path(args.json).is_file() else {"cases": {}}
    if args.doc:
        write_between(ROOT / "docs" / "close_loop.md", "effect_information", table(data))
        return 0
    windows = [float(w) for w in args.windows.split(",")]
    layouts = [s for s in args.layouts.split(",") if s]
    numbers = {}
    for n in range(1, 23):   # the first recovery measurement of each layout
        lay = make_case("recovery", n).layout
        if lay in layouts and lay not in numbers:
            numbers[lay] = n
    data.update({"command": " ".join(sys.argv), "round_hypotheses": ROUND_HYPOTHESES, "q": Q, "alpha": ALPHA})
    with ChainSimulator() as sim:
        for proto in [s for s in args.protocols.split(",") if s]:
            for lay, n in numbers.items():
                key = f"{lay}_{proto}_{args.seconds:g}"
                if key in data["cases"]:
                    continue
                data["cases"][key] = rig_case(n, proto, args.seconds, windows, Path(args.work), sim)
                r = data["cases"][key]["windows"][f"{max(windows):g}"]
                print(f"{key}: ripple a90 {r['motor_ripple_N']['median']:.0f} N, runout 1 lobe "
                      f"{r['wheel_oor_1_um']['median']:.2g} um ({data['cases'][key]['cpu_s']:.0f} CPU-s)",
                      file=sys.stderr)
                if args.json:
                    write_json_atomic(Path(args.json), data)
    for cart in [int(c) for c in args.release_carts.split(",") if c]:
        key = f"layout7_release_cart{cart}"
        if key not in data["cases"]:
            data["cases"][key] = release_case(cart)
            if args.json:
                write_json_atomic(Path(args.json), data)
    print(table(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())
