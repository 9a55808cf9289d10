#!/usr/bin/env python3
"""Detection rates of the closed loop on the records a sorter makes (issue 53, item 1).

Each case is a start-stop record of the rig (`lss rig --protocol start-stop`,
the recovery set), the transducer cart where the rig parks it, closed as
`lss close-loop REC --model LW` does (identification.loop.on_record: the base
by the front door, then one round of the loop) with the budgets of the
make-test case (`BASE`, `LOOP`). Record r of a case is measurement
`MEASUREMENTS[r % 7]` (one per layout 1-7), drawn with rig seed SEED0 + r
(speeds, pretension, parking place, noise: another sorter of the layout each
time) and effect seed 1 + r (phases, pitch, joint); the effect's size is set
(`rig.run_measurement(effect_values=...)`), so one family is run at
amplitudes that bracket its threshold. Clean records: the same draws without
an effect, a false confirmation being any effect confirmed.

A row holds the verdict, what was found, and the record's own reach of the
family (identification.loop.reach: the size its tests confirm in 90 % of
records of the kind, at the base), so a miss can be read as the loop's or the
record's. Every case is written atomically to RESULTS/<case>.json with the
code's stamp; a rerun skips the cases already there (`--stale` reruns those
of other code).

    .venv/bin/python benchmarks/bench_close_loop_start_stop.py run [--part clean|detect|all] [--records 20]
        [--families wheel_oor_2,motor_ripple] [--amplitudes-index 1,2] [--layouts 1,2,4] [--limit N] [--stale]
    .venv/bin/python benchmarks/bench_close_loop_start_stop.py report [--figure FILE]

Cost: one case is a base identification and a round of the loop on 1.2 s,
about 300 CPU-s on layout 7 and 670 on layout 2 (52 and 169 carts); layout 3
(685 carts) about ten times layout 7's.
"""
from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import logging
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_common import ROOT, hash_sources  # noqa: E402  (sets one BLAS thread)
from bench_close_loop_rates import code_of, figure, summarise, table  # noqa: E402

from lss_fmu.atomic import write_json_atomic  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "close_loop_start_stop"
SUMMARY = ROOT / "benchmarks" / "results" / "close_loop_start_stop.json"
WORK = ROOT / "build" / "bench_close_loop_start_stop"
MEASUREMENTS = (1, 5, 9, 12, 13, 19, 20)   # the first recovery measurement of layouts 1-7
SECONDS = 1.2                              # started from rest, braked at 1 s
SEED0 = 1000                               # rig seeds: other sorters than the recovery set's
CLEAN_RECORDS = 42

# family -> (unit, amplitudes, what), as bench_close_loop_rates.FAMILIES; SIZE: the FMU values of an amplitude
FAMILIES = {
    "wheel_oor_1": ("um", (25.0, 50.0, 100.0, 200.0, 400.0), "radial runout, 1 lobe, phases drawn"),
    "wheel_oor_2": ("um", (10.0, 25.0, 50.0, 100.0, 200.0), "radial runout, 2 lobes, phases drawn"),
    "motor_ripple": ("N", (2.0, 5.0, 15.0, 50.0, 150.0), "thrust ripple, pitch and phase drawn"),
    "track_bump": ("mm", (0.1, 0.25, 0.5, 1.0, 2.0), "|height| at the drawn joint, sign and length drawn"),
    "joint_clearance": ("um", (2.0, 5.0, 15.0, 50.0), "gap in every joint"),
    "mass": ("1", (0.02, 0.05, 0.15, 0.3), "transducer cart's mass factor - 1, the others equal"),
}
EFFECT = {"wheel_oor_1": "wheel_oor", "wheel_oor_2": "wheel_oor", "motor_ripple": "motor_ripple",
          "track_bump": "track_bump", "joint_clearance": "joint_clearance", "mass": "mass"}


def size(family: str, a: float, drawn: dict) -> dict:
    """The FMU values of amplitude `a` of `family`; `drawn`: the effect's drawn parameters (a bump keeps its sign)."""
    if family.startswith("wheel_oor"):
        return {"effects.wheel_oor.amplitude": a * 1e-6, "effects.wheel_oor.order": int(family[-1])}
    if family == "motor_ripple":
        return {"effects.motor_ripple.amplitude": a}
    if family == "track_bump":
        return {"effects.track_bump.height": a * 1e-3 * (1.0 if drawn["effects.track_bump.height"] >= 0 else -1.0)}
    if family == "joint_clearance":
        return {"effects.joint_clearance.gap": a * 1e-6}
    if family == "mass":
        return {"effects.mass.transducer_factor": 1.0 + a, "effects.mass.spread": 0.0}
    raise ValueError(f"family {family!r}: the families are {', '.join(FAMILIES)}")


def budgets():
    """(front door settings, loop settings): the make-test case's (tests/test_close_loop_start_stop.py)."""
    from identification.loop.settings import LoopSettings
    from identification.pipeline.settings import Settings
    return (Settings(max_evals=120, refine_evals=80, restarts=0, shrink=False),
            LoopSettings(max_evals=120, refine_evals=40, base_refine_evals=40, profile_points=5, candidates=3))


def cases(part: str, records: int, families=None, amp_index=None, layouts=None) -> list:
    """The cases, clean ones first; `layouts`: numbers 1-7 to keep (records of other layouts are skipped)."""
    def keep(r):
        return layouts is None or (r % len(MEASUREMENTS)) + 1 in layouts
    out = []
    if part in ("clean", "all"):
        out += [{"id": f"ss_clean_r{r:02d}", "kind": "clean", "source": "rig start-stop", "record": r}
                for r in range(CLEAN_RECORDS) if keep(r)]
    if part in ("detect", "all"):
        for fam, (_, amps, _) in FAMILIES.items():
            if families and fam not in families:
                continue
            for ia, a in enumerate(amps):
                if amp_index is None or ia in amp_index:
                    out += [{"id": f"ss_{fam}_a{ia}_r{r:02d}", "kind": "effect", "family": fam, "amplitude": a,
                             "amp_index": ia, "record": r, "source": "rig start-stop"}
                            for r in range(records) if keep(r)]
    return out


def record(case: dict, folder: Path):
    """The case's record, made once into `folder` (the rig's answers beside it)."""
    from lss_fmu import measurement as M
    from lss_fmu.rig import folder_name, make_case, run_measurement
    from lss_fmu.runner import ChainSimulator
    r = int(case["record"])
    number, seed = MEASUREMENTS[r % len(MEASUREMENTS)], SEED0 + r
    where = folder / folder_name(number)
    if not (where / "meta.json").is_file():
        kw = {}
        if case["kind"] == "effect":
            eff = EFFECT[case["family"]]
            drawn = make_case("recovery", number, seed, effects=[eff], effect_seed=1 + r, protocol="start-stop",
                              lap_seconds=SECONDS).effects[eff]["parameters"]
            kw = {"effects": [eff], "effect_seed": 1 + r,
                  "effect_values": size(case["family"], float(case["amplitude"]), drawn)}
        with ChainSimulator() as sim:
            run_measurement("recovery", number, folder, sim, seed=seed, protocol="start-stop", lap_seconds=SECONDS,
                            overwrite=True, **kw)
    return M.load_measurement(where)


def run_case(case: dict) -> dict:
    from identification.loop.on_record import close_loop_record
    from lss_fmu.rig import load_truth
    t0, c0 = time.time(), time.process_time()
    work = WORK / case["id"]
    meas = record(case, work / "data")
    base, loop = budgets()
    res = close_loop_record(meas, "LW", work / "loop", settings=base, loop_settings=loop, rounds=1)
    rnd = res.rounds[0]
    truth = load_truth(meas).get("effects", {})
    target = EFFECT.get(case.get("family"))
    reach = [r.to_dict() for r in rnd.reach if r.effect == target]
    ev = rnd.evidence
    return {**case, "layout": meas.layout, "number": meas.meta.get("number"), "truth": truth,
            "found": res.found, "outcome": res.outcome, "verdict": res.verdict,
            "amplitude_found": rnd.amplitude if rnd.confirmed else None, "reach": reach,
            "evidence": None if ev is None else {"effect": ev.effect, "T": ev.lr.T, "p_adj": ev.lr.p_adj,
                                                 "dbic": ev.lr.dbic, "holdout_gain": ev.holdout.gain
                                                 if ev.holdout else None},
            "tests": [(t.effect, t.lr.p_adj, t.lr.dbic, t.supported) for t in rnd.tests],
            "S_base_per_sample": rnd.S_base / res.problem.samples.size,
            "wall_s": time.time() - t0, "cpu_s": time.process_time() - c0}


def code_stamp() -> str:
    """What decides a case's outcome: the sources (identification, lss_fmu, fmu_src), this file's case making."""
    h = hash_sources(hashlib.sha256())
    for fn in (size, budgets, cases, record, run_case):
        h.update(inspect.getsource(fn).encode())
    h.update(repr((MEASUREMENTS, SECONDS, SEED0, FAMILIES)).encode())
    return h.hexdigest()[:12]


def cmd_run(args) -> int:
    logging.basicConfig(level=logging.ERROR)
    fams = [f for f in args.families.split(",") if f] if args.families else None
    unknown = sorted(set(fams or ()) - set(FAMILIES))
    if unknown:
        raise SystemExit(f"--families: {unknown[0]!r} is not one of {', '.join(FAMILIES)}")
    amp_index = [int(i) for i in args.amplitudes_index.split(",")] if args.amplitudes_index else None
    layouts = [int(i) for i in args.layouts.split(",")] if args.layouts else None
    results = Path(args.results)
    results.mkdir(parents=True, exist_ok=True)
    stamp, done = code_stamp(), 0
    print(f"code stamp {stamp}", flush=True)
    for case in cases(args.part, args.records, fams, amp_index, layouts):
        path = results / f"{case['id']}.json"
        if path.is_file() and (not args.stale or json.loads(path.read_text()).get("code_stamp") == stamp):
            continue
        try:
            res = run_case(case)
        except Exception as exc:   # a case that cannot run is recorded, the benchmark goes on
            import traceback
            res = {**case, "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()}
        res["code_stamp"] = stamp
        write_json_atomic(path, res)
        done += 1
        print(f"{case['id']}: {res.get('outcome', res.get('error'))}, found {res.get('found')} "
              f"({res.get('cpu_s', 0):.0f} CPU-s)", flush=True)
        if args.limit and done >= args.limit:
            break
    return 0


def cmd_report(args) -> int:
    results = [json.loads(p.read_text()) for p in sorted(Path(args.results).glob("*.json"))]
    s = summarise(results, FAMILIES, budget={k: v.to_dict() for k, v in zip(("identify", "close_loop"), budgets())})
    s["code"] = code_of(results, code_stamp())
    if Path(args.results).resolve() == RESULTS.resolve():
        write_json_atomic(SUMMARY, s)
    if args.figure:
        figure(s, Path(args.figure), what="start-stop records of layouts 1-7")
    print(table(s))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--part", choices=("clean", "detect", "all"), default="all")
    r.add_argument("--records", type=int, default=20, help="records per family and amplitude")
    r.add_argument("--families", default=None)
    r.add_argument("--amplitudes-index", default=None)
    r.add_argument("--layouts", default=None, help="layout numbers to keep, e.g. 1,2,4,5,6,7")
    r.add_argument("--limit", type=int, default=0, help="stop after this many new cases (0: all)")
    r.add_argument("--results", default=str(RESULTS), help="folder of the case files")
    r.add_argument("--stale", action="store_true", help="rerun the cases stored under another code stamp")
    r.set_defaults(run=cmd_run)
    p = sub.add_parser("report")
    p.add_argument("--figure", default=None)
    p.add_argument("--results", default=str(RESULTS), help="folder of the case files")
    p.set_defaults(run=cmd_report)
    args = ap.parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
