#!/usr/bin/env python3
"""The recovery table: the true CoRs recovered by `lss campaign` with its
defaults, per measurement of the recovery set.

The virtual transducer cart records each of the 22 recovery measurements
(`lss rig --set recovery`, LW truth with Table 3's CoRs) `--repeats` times,
record k in DATA_rk/mNN; the campaign groups the records of a measurement
by their folder name and identifies them jointly with LW through the front
door's pipeline (identification.pipeline.driver, the defaults or `--settings`),
resumable. Each result is then compared with its answer file, which the
identification never reads: |identified - true| per CoR, whether the CoR
was claimed (identifiable) and its interval holds the truth, f / f(truth)
(f(truth): the problem's objective at the true values on the window the
result is for), CPU time.

    .venv/bin/python benchmarks/bench_recovery.py --measurements 1-22 --json benchmarks/results/recovery.json
    .venv/bin/python benchmarks/bench_recovery.py --table --json benchmarks/results/recovery.json

`--set drawn --rig-seed S` runs the same table on cases the method was not
tuned on: CoRs drawn over the box, another sorter's draws and noise.

Everything is kept under --work (the records, the campaign's results and
journals): stopped and started again it resumes; the JSON is rewritten as
each measurement finishes, every row stamped with the code it ran on.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench_common import ROOT, hash_sources, write_between  # noqa: E402
from identification.pipeline.campaign import run_campaign  # noqa: E402
from identification.objective.joint import own  # noqa: E402
from identification.pipeline.driver import build_problem  # noqa: E402
from identification.pipeline.settings import load_settings  # noqa: E402
from identification.pipeline.windowing import truncated  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS, SYMBOL, TRIGGER  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import DEFAULT_SEED, generate_set, load_truth, parse_numbers, true_design_values  # noqa: E402

TARGET = {"e_JA": 0.03, "e_SW": 0.03, "e_RW": 0.03, "e_JR": 0.05}
HEADLINE = ("e_JA", "e_SW", "e_RW")   # the CoRs a start-stop determines; the table's count is on these


def code_stamp() -> str:
    """A hash of the code that decides a row (identification, lss_fmu, fmu_src)."""
    return hash_sources(hashlib.sha256()).hexdigest()[:12]


def f_truth(result: dict, settings) -> float:
    """The objective at the true values of every record (each its own trigger
    point) on the window the result is for."""
    records = [load_measurement(p) for p in result["records"]]
    p = build_problem(records, result["model"], settings)
    try:
        truth = {}
        for k, m in enumerate(records):
            tk = true_design_values(load_truth(m))
            truth.update(tk if k == 0 else {own(k): tk[TRIGGER]})
        q = truncated(p, float(result["window_s"])) if result["window_s"] < float(p.times[-1]) - 1e-9 else p
        return float(q(np.array([truth[n] for n in q.free])))
    finally:
        for part in getattr(p, "parts", [p]):
            part.sim.close()


def row_of(result: dict, settings, stamp: str) -> dict:
    truth = load_truth(Path(result["records"][0]))
    ft = f_truth(result, settings)
    row = {"measurement": result["sorter"], "number": result.get("number"), "layout": result.get("layout"),
           "records": len(result["records"]), "f": result["f"], "f_truth": ft,
           "ratio": result["f"] / ft if ft > 0 else float("nan"), "cpu_s": result.get("cpu_s"),
           "nfev": result["nfev"], "window_s": result.get("window_s"),
           "windows": [w["window_s"] for w in result.get("windows") or []], "code": stamp}
    for k in CORS:
        s = SYMBOL[k]
        true, got = truth["cor"][s], result["values"][s]
        iv = (result.get("interval") or {}).get(s) or {}
        row[s] = {"true": true, "identified": got, "error": got - true, "interval": iv,
                  "covers": bool(iv) and iv.get("lower", np.inf) <= true <= iv.get("upper", -np.inf),
                  "identifiable": iv.get("identifiable")}
    return row


def hit(q: dict, s: str) -> bool:
    """A CoR counted as recovered: claimed (identifiable) and within its tolerance of the truth."""
    return q[s]["identifiable"] is not False and abs(q[s]["error"]) <= TARGET[s]


def summary(rows: list) -> dict:
    out = {"n": len(rows), "ratio_median": float(np.median([q["ratio"] for q in rows])) if rows else None,
           "within_2x": int(sum(q["ratio"] <= 2.0 for q in rows)),
           "all_three_claimed_within": int(sum(all(hit(q, s) for s in HEADLINE) for q in rows)),
           "cpu_s_total": float(sum(q["cpu_s"] or 0.0 for q in rows)),
           "codes": dict(Counter(q.get("code") for q in rows))}
    for s, tol in TARGET.items():
        out[s] = {"within": int(sum(abs(q[s]["error"]) <= tol for q in rows)), "tolerance": tol,
                  "claimed_within": int(sum(hit(q, s) for q in rows)),
                  "not_identifiable": int(sum(q[s]["identifiable"] is False for q in rows)),
                  "interval_covers": int(sum(q[s]["covers"] for q in rows)),
                  "median_abs_error": float(np.median([abs(q[s]["error"]) for q in rows])) if rows else None}
    return out


def table(rows: list) -> str:
    """Markdown: per measurement the true e_JA, e_SW, e_RW, f / f(truth), each
    CoR's error with its interval's sd (n.i.: reported not identifiable),
    whether e_JA, e_SW, e_RW's intervals hold the truth, the window used (and
    the ones tried before it), CPU."""
    head = ("| meas | layout | true JA/SW/RW | f / f(truth) | e_JA err (sd) | e_SW err (sd) | e_RW err (sd) | "
            "e_JR err | intervals cover (JA/SW/RW) | window s | CPU s |")
    lines = [head, "|" + "---|" * 11]
    for q in rows:
        def cell(s, sd=True):
            e, iv = q[s]["error"], q[s]["interval"] or {}
            if q[s]["identifiable"] is False:
                return f"{e:+.3f} n.i."
            return f"{e:+.3f} ({iv.get('sd', float('nan')):.3f})" if sd else f"{e:+.3f}"
        cov = "/".join("y" if q[s]["covers"] else "n" for s in HEADLINE)
        tried = q.get("windows") or []
        win = "" if q.get("window_s") is None else f"{q['window_s']:.2g}"
        if len(tried) > 1:
            win += " (" + ", ".join(f"{w:.2g}" for w in tried[:-1]) + ")"
        true = "/".join(f"{q[s]['true']:.2f}" for s in HEADLINE)
        lines.append(f"| {q['number']} | {str(q['layout']).replace('layout', '')} | {true} | {q['ratio']:.3f} | "
                     f"{cell('e_JA')} | {cell('e_SW')} | {cell('e_RW')} | {cell('e_JR', False)} | {cov} | {win} | "
                     f"{q['cpu_s'] or 0:.0f} |")
    return "\n".join(lines)


def doc_text(entry: dict, source: str) -> str:
    """The table of a JSON with its summary in words, for docs/recovery_table.md."""
    sm, rows = entry["summary"], entry["rows"]
    codes = ", ".join(f"{n} rows of code {c}" for c, n in sm.get("codes", {}).items())
    return (f"From `{source}` ({entry.get('protocol')}, {entry.get('repeats')} records a measurement, rig seed "
            f"{entry.get('rig_seed', 'default')}; {codes}).\n\n"
            f"**{sm['all_three_claimed_within']} of {sm['n']}** measurements with e_JA, e_SW and e_RW claimed and "
            f"within 0.03; f / f(truth) median {sm['ratio_median']:.3f}; intervals holding the truth: "
            + ", ".join(f"{s} {sm[s]['interval_covers']} of {sm['n']}" for s in HEADLINE)
            + f"; {sm['cpu_s_total']:.0f} CPU-s in all.\n\n{table(rows)}")


def set_fmu(data: Path):
    """The FMU that made most of the set already in `data` (a rebuild since, e.g.
    by the tests, is another file: the set stays one FMU's), or None."""
    shas = Counter()
    for t in (data / "answers").glob("m*/truth.json"):
        shas[json.loads(t.read_text()).get("fmu_sha256", "")[:12]] += 1
    for sha, _ in shas.most_common():
        hit_ = sorted((data / "fmu").glob(f"LSSChain-{sha}*.fmu")) if sha else []
        if hit_:
            return hit_[0]
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="build/bench_recovery")
    ap.add_argument("--protocol", default="start-stop")
    ap.add_argument("--set", default="recovery", choices=("recovery", "drawn"), dest="set_name",
                    help="the rig's set: Table 3's CoRs, or CoRs drawn over the box (cases the method was not "
                         "tuned on)")
    ap.add_argument("--rig-seed", type=int, default=DEFAULT_SEED,
                    help="the rig's seed: another sorter's speeds, pretensions, parking places and noise")
    ap.add_argument("--measurements", default="1-22")
    ap.add_argument("--repeats", type=int, default=3, help="records per measurement, identified jointly")
    ap.add_argument("--seconds", type=float, default=None, help="record length, s (default: the protocol's)")
    ap.add_argument("--settings", default=None, help="an expert's settings file (default: the campaign's defaults)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--table", action="store_true", help="print the Markdown table of --json and stop")
    ap.add_argument("--doc", action="store_true",
                    help="write the table and summary of --json into docs/recovery_table.md and stop")
    args = ap.parse_args(argv)
    if args.table or args.doc:
        entry = json.loads(Path(args.json).read_text())
        if args.doc:
            write_between(ROOT / "docs" / "recovery_table.md", entry.get("set", "recovery"), doc_text(entry, args.json))
            return 0
        print(f"{table(entry['rows'])}\n\n{json.dumps(entry['summary'], indent=1)}")
        return 0
    if args.repeats < 1:
        raise SystemExit(f"--repeats {args.repeats}: must be at least 1")
    numbers = parse_numbers(args.measurements)
    settings = load_settings(args.settings)
    stamp = code_stamp()
    base = Path(args.work) / args.protocol
    if args.set_name != "recovery" or args.rig_seed != DEFAULT_SEED:
        base = base.with_name(f"{args.protocol}_{args.set_name}_s{args.rig_seed}")
    dirs = [base / ("data" if k == 0 else f"data_r{k}") for k in range(args.repeats)]
    fmu = set_fmu(dirs[0])
    t0, gen_cpu = time.time(), 0.0
    for k, d in enumerate(dirs):
        gen = generate_set(args.set_name, d, numbers, seed=args.rig_seed, workers=args.workers, protocol=args.protocol,
                           progress=not args.no_progress,
                           repeat=k, lap_seconds=args.seconds, log=lambda msg: print(msg, file=sys.stderr), fmu=fmu)
        gen_cpu += sum(r.get("cpu_s", 0.0) for r in gen if "cpu_s" in r)
    # a table grows over several sessions (build/ is not kept): the stored rows of other measurements stay
    old = json.loads(Path(args.json).read_text()) if args.json and Path(args.json).exists() else {}
    if old and old.get("settings") != settings.to_dict():
        raise SystemExit(f"{args.json}: holds rows of other settings; give another --json")
    if old and (old.get("set", "recovery"), old.get("rig_seed", DEFAULT_SEED)) != (args.set_name, args.rig_seed):
        raise SystemExit(f"{args.json}: holds rows of set {old.get('set', 'recovery')} seed "
                         f"{old.get('rig_seed', DEFAULT_SEED)}; give another --json")
    # and so do this run's rows made by this code (finished already: the campaign does not run them again)
    rows = {q["number"]: q for q in old.get("rows", []) if q["number"] not in numbers or q.get("code") == stamp}

    def write() -> None:
        ordered = sorted(rows.values(), key=lambda q: q["number"] or 0)
        report = {"command": " ".join(sys.argv), "protocol": args.protocol, "repeats": args.repeats,
                  "set": args.set_name, "rig_seed": args.rig_seed,
                  "settings": settings.to_dict(), "rows": ordered, "summary": summary(ordered),
                  "wall_s": time.time() - t0, "generation_cpu_s": gen_cpu}
        if args.json:
            write_json_atomic(args.json, report)
        return report

    def done(result: dict) -> None:
        if result.get("number") in numbers:
            rows[result["number"]] = row_of(result, settings, stamp)
            write()

    out = base / f"campaign_k{args.repeats}"
    results = run_campaign(dirs, ["LW"], out, settings=settings, workers=args.workers, seed=args.seed,
                           on_result=done, progress=not args.no_progress)
    for r in results:   # the ones finished in an earlier session of this work folder
        if r.get("number") in numbers and r["number"] not in rows:
            done(r)
    report = write()
    print(f"\n{table(report['rows'])}\n\n{json.dumps(report['summary'], indent=1)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
