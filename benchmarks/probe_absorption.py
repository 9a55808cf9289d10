#!/usr/bin/env python3
"""Which base variable absorbs an undeclared effect: on a rig record with an
effect switched on (its truth in the answers folder) and the closed loop's
base result for it, S (chi^2 in the declared noise's metric, after the tare)

- at the true design values, without the effect and with it (the noise
  floor: what a model with the effect reaches);
- at the base point without the effect (what the loop starts from);
- at the true values with one variable moved to the base's value, for each
  free variable, without and with the effect.

A variable whose base value alone takes S without the effect from far above
the floor to near it is the one the base moved to absorb the effect: the
loop then sees little left to explain (docs/close_loop.md).

    .venv/bin/python benchmarks/probe_absorption.py REC LOOP_OUT [--json FILE]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from identification.loop.close_loop import base_from_result  # noqa: E402
from identification.objective.problem import from_measurement, weighted_residual  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import symbol  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import load_truth, true_design_values  # noqa: E402


def probe(record: Path, loop_out: Path, model: str = "LW") -> dict:
    m = load_measurement(record)
    p = from_measurement(m, model, tare=True, objective="likelihood")
    truth = load_truth(m)
    effect = {k: v for e in truth["effects"].values() for k, v in e["parameters"].items()}
    if not effect:
        raise SystemExit(f"{record}: its truth has no undeclared effect")
    tv = true_design_values(truth)
    xt = np.array([tv[n] for n in p.free])
    xb = base_from_result(loop_out / "base", p)
    w = 1.0 / np.asarray(p.noise, float) ** 2

    def S(x, extra=None) -> float:
        return weighted_residual(p, p.simulate(x, extra), w)[1]

    rows = []
    for i, n in enumerate(p.free):
        x = xt.copy()
        x[i] = xb[i]
        rows.append({"variable": symbol(n), "truth": float(xt[i]), "base": float(xb[i]),
                     "S_without": S(x), "S_with": S(x, effect)})
    return {"record": str(record), "effects": sorted(truth["effects"]), "samples": int(p.samples.size),
            "S_truth_without": S(xt), "S_truth_with": S(xt, effect), "S_base_without": S(xb), "rows": rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("record", type=Path)
    ap.add_argument("loop_out", type=Path, help="the loop's output folder (its base/result.json)")
    ap.add_argument("--model", default="LW")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    r = probe(args.record, args.loop_out, args.model)
    print(f"{r['record']} ({', '.join(r['effects'])}, {r['samples']} samples): S at the truth "
          f"{r['S_truth_without']:.0f} without the effect, {r['S_truth_with']:.0f} with it; "
          f"the base {r['S_base_without']:.0f}")
    print("| variable | truth | base | S, truth with the base's value: without the effect | with it |")
    print("|---|---|---|---|---|")
    for q in r["rows"]:
        print(f"| {q['variable']} | {q['truth']:.5g} | {q['base']:.5g} | {q['S_without']:.0f} | {q['S_with']:.0f} |")
    if args.json:
        write_json_atomic(args.json, r)
    return 0


if __name__ == "__main__":
    sys.exit(main())
