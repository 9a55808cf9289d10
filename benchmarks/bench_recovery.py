#!/usr/bin/env python3
"""Recovery of the true CoRs from the recovery set, per protocol (issue 17).

For each protocol: the 22 recovery measurements of the virtual transducer
cart (`lss rig --set recovery --protocol P`, LW truth with Table 3's CoRs),
each identified with LW and the paper's ten design variables free through
`lss campaign` (local processes, resumable), then compared with the answer
files: |identified - true| per CoR, f / f(truth) (f(truth): the problem's
objective at the true values, what noise and offsets leave), the interval
of each CoR and whether it holds the truth, CPU time.

    .venv/bin/python benchmarks/bench_recovery.py --protocols start-up --measurements 1-22 \\
        --max-evals 600 --presolve 200 --refine-evals 160 --window 2.5 \\
        --json benchmarks/results/recovery_start-up.json

Everything is kept under --work: the sets, the campaign's results and
journals; stopped and started again it resumes where it was.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from bench_common import code_version  # noqa: E402
from identification.campaign import run_campaign  # noqa: E402
from identification.joint import JointProblem  # noqa: E402
from identification.problem import drive_known, from_measurement  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS, SYMBOL  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import generate_set, load_truth, parse_numbers, true_design_values  # noqa: E402

TARGET = {"e_JA": 0.03, "e_SW": 0.03, "e_RW": 0.03, "e_JR": 0.05}


def _truth_x(truth: dict, free) -> np.ndarray:
    vals = true_design_values(truth)
    return np.array([vals[n] for n in free])


def f_truth(meas_dir: Path, window, tare: bool, objective: str = "pointwise") -> float:
    """The objective at the true values (the floor the identification can reach)."""
    m = load_measurement(meas_dir)
    p = from_measurement(m, "LW", window=window, tare=tare, objective=objective)
    try:
        return float(p(_truth_x(load_truth(m), p.free)))
    finally:
        p.sim.close()


def rows_of(results: list, data: Path, window, tare: bool, cache: dict, objective: str = "pointwise") -> list:
    rows = []
    for r in results:
        meas_dir = Path(r["measurement_dir"])
        truth = load_truth(meas_dir)
        key = r["measurement"]
        if key not in cache:
            cache[key] = f_truth(meas_dir, window, tare, objective)
        row = {"measurement": key, "number": r.get("number"), "layout": r.get("layout"), "code": r.get("code"),
               "f": r["f"], "f_truth": cache[key], "ratio": r["f"] / cache[key] if cache[key] > 0 else float("nan"),
               "cpu_s": r.get("cpu_s"), "nfev": r["nfev"], "refined": r.get("refined"),
               "protocol": (r.get("protocol") or {}).get("name", "steady"),
               "window_s": r.get("window_s"), "windows": [w["window_s"] for w in r.get("windows") or []]}
        for k in CORS:
            s = SYMBOL[k]
            true = truth["cor"][s]
            got = r["values"][s]
            iv = (r.get("interval") or {}).get(s) or {}
            row[s] = {"true": true, "identified": got, "error": got - true, "interval": iv,
                      "covers": bool(iv) and iv.get("lower", np.inf) <= true <= iv.get("upper", -np.inf),
                      "identifiable": iv.get("identifiable")}
        rows.append(row)
    return sorted(rows, key=lambda q: q["number"] or 0)


def summary(rows: list) -> dict:
    out = {"n": len(rows), "ratio_median": float(np.median([q["ratio"] for q in rows])) if rows else None,
           "within_2x": int(sum(q["ratio"] <= 2.0 for q in rows)),
           "cpu_s_total": float(sum(q["cpu_s"] or 0.0 for q in rows))}
    for s, tol in TARGET.items():
        out[s] = {"within": int(sum(abs(q[s]["error"]) <= tol for q in rows)), "tolerance": tol,
                  "not_identifiable": int(sum(q[s]["identifiable"] is False for q in rows)),
                  "interval_covers": int(sum(q[s]["covers"] for q in rows)),
                  "median_abs_error": float(np.median([abs(q[s]["error"]) for q in rows])) if rows else None}
    return out


def table(rows: list) -> str:
    """Markdown: per record f / f(truth), each CoR's error with its interval's
    sd (n.i.: reported not identifiable), whether e_JA, e_SW, e_RW's intervals
    hold the truth, the window used (and the ones tried before it), CPU."""
    head = ("| meas | layout | f / f(truth) | e_JA err (sd) | e_SW err (sd) | e_RW err (sd) | e_JR err | intervals "
            "cover (JA/SW/RW) | window s | CPU s |")
    lines = [head, "|" + "---|" * 10]
    for q in rows:
        def cell(s, sd=True):
            e, iv = q[s]["error"], q[s]["interval"] or {}
            if q[s]["identifiable"] is False:
                return f"{e:+.3f} n.i."
            return f"{e:+.3f} ({iv.get('sd', float('nan')):.3f})" if sd else f"{e:+.3f}"
        cov = "/".join("y" if q[s]["covers"] else "n" for s in ("e_JA", "e_SW", "e_RW"))
        tried = q.get("windows") or []
        win = "" if q.get("window_s") is None else f"{q['window_s']:.2g}"
        if len(tried) > 1:
            win += " (" + ", ".join(f"{w:.2g}" for w in tried[:-1]) + ")"
        lines.append(f"| {q['number']} | {q['layout'].replace('layout', '')} | {q['ratio']:.3f} | {cell('e_JA')} | "
                     f"{cell('e_SW')} | {cell('e_RW')} | {cell('e_JR', False)} | {cov} | {win} | "
                     f"{q['cpu_s'] or 0:.0f} |")
    return "\n".join(lines)


def joint_records(data: Path, out: Path, numbers, args, tare: bool) -> list:
    """Each measurement's `--repeats` records identified together
    (identification.joint), with `--cors-only` the six layout-dependent
    variables at their true values (the diagnostic that separates the
    optimiser from the model), else all ten free. One result file per
    measurement, written atomically (a stopped run resumes)."""
    from identification.joint import own
    from identification.staged import run
    (out / "journals").mkdir(parents=True, exist_ok=True)
    rows = []
    for n in numbers:
        path = out / f"m{n:02d}.json"
        if not path.exists():
            m = load_measurement(data / f"m{n:02d}")
            parts, truth = [], {}
            for k in range(args.repeats):   # record k: repeat k of the protocol (the chain parked elsewhere)
                folder = (data if k == 0 else data.parent / f"data_r{k}") / f"m{n:02d}"
                mk = load_measurement(folder)
                tk = true_design_values(load_truth(mk))
                pk = from_measurement(mk, "LW", window=args.window, tare=tare, objective=args.objective)
                parts.append(drive_known(pk, tk) if args.cors_only else pk)
                truth = {**tk, **truth} if k == 0 else {**truth, own(k): tk[own(0)]}
            p = parts[0] if len(parts) == 1 else JointProblem(parts)
            c0, code = time.process_time(), code_version()   # the code at the start: HEAD may move during a run
            try:
                more = {"start": args.start} if args.grown else {}
                if args.grown and args.halvings:
                    more["halvings"] = args.halvings
                res = run(p, args.staged, args.shrink, args.grown, max_evals=args.max_evals, seed=args.seed,
                          progress=False, restarts=args.restarts, refine_evals=args.refine_evals, uncertainty=True,
                          **more,
                          presolve=0 if args.cors_only else args.presolve,
                          journal=out / "journals" / f"m{n:02d}.jsonl")
                r = res.to_dict()
                r.update({"cpu_s": time.process_time() - c0, "number": n, "layout": m.layout,
                          "measurement": res.problem.name, "measurement_dir": str(data / f"m{n:02d}"),
                          "records": len(parts), "code": code})
                # at the window used
                r["f_truth"] = float(res.problem(np.array([truth[q] for q in res.problem.free])))
            finally:
                for q in parts:
                    q.sim.close()
            write_json_atomic(path, r)
        rows.append(json.loads(path.read_text()))
    return rows


def set_fmu(data: Path):
    """The FMU that made most of the set already in `data` (a rebuild since, e.g.
    by the tests, is another file: the set stays one FMU's), or None."""
    from collections import Counter
    shas = Counter()
    for t in (data / "answers").glob("m*/truth.json"):
        shas[json.loads(t.read_text()).get("fmu_sha256", "")[:12]] += 1
    for sha, _ in shas.most_common():
        hit = sorted((data / "fmu").glob(f"LSSChain-{sha}*.fmu")) if sha else []
        if hit:
            return hit[0]
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="build/bench_recovery")
    ap.add_argument("--protocols", default="start-up")
    ap.add_argument("--measurements", default="1-22")
    ap.add_argument("--max-evals", type=int, default=600)
    ap.add_argument("--presolve", type=int, default=200)
    ap.add_argument("--refine-evals", type=int, default=160)
    ap.add_argument("--restarts", type=int, default=0,
                    help="with --grown: while a record is off the noise at the chosen window, again with the "
                         "next seed, up to N times (folder suffix _rN)")
    ap.add_argument("--window", type=float, default=None)
    ap.add_argument("--no-tare", action="store_true")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--objective", default="pointwise", choices=("pointwise", "likelihood"),
                    help="the identification's objective (identification.problem)")
    ap.add_argument("--repeats", type=int, default=1,
                    help="with --cors-only: identify K records of each measurement together (lss rig --repeat "
                         "0..K-1 of a start-up or start-stop; identification.joint)")
    ap.add_argument("--staged", action="store_true",
                    help="identification.staged: the layout-dependent variables by Levenberg-Marquardt, the complex "
                         "on the CoRs, Levenberg-Marquardt on all ten (--presolve, --max-evals, --refine-evals)")
    ap.add_argument("--shrink", action="store_true",
                    help="identification.windowing: shorter windows (1.5, 1.2, 1.0 s) while a CoR is rough")
    ap.add_argument("--grown", action="store_true",
                    help="identification.identify_grown: the complex on the first 0.3 s (--max-evals), then "
                         "Levenberg-Marquardt over growing windows (--refine-evals after it)")
    ap.add_argument("--start", default="complex", choices=("complex", "single", "auto"),
                    help="with --grown and --repeats > 1: where the joint fit starts (identification.joint_start: "
                         "'single', the first record alone, then the others' trigger points; 'auto', the "
                         "complex and, where its first window is above the noise, 'single' as well)")
    ap.add_argument("--halvings", type=int, default=0,
                    help="with --grown: a window's step that leaves the noise is taken again in 2^N shorter ones")
    ap.add_argument("--cors-only", action="store_true",
                    help="the layout-dependent variables at their true values, the CoRs free (diagnostic)")
    ap.add_argument("--table", action="store_true", help="print the Markdown tables of --json and stop")
    args = ap.parse_args(argv)
    if args.table:
        for label, entry in json.loads(Path(args.json).read_text())["protocols"].items():
            print(f"## {label}\n\n{table(entry['rows'])}\n\n{json.dumps(entry['summary'], indent=1)}\n")
        return 0
    numbers = parse_numbers(args.measurements)
    tare = not args.no_tare
    report = {"command": " ".join(sys.argv), "settings": vars(args), "protocols": {}}
    if args.json and Path(args.json).exists():
        report = {**json.loads(Path(args.json).read_text()), "command": report["command"],
                  "settings": report["settings"]}
    for protocol in [p.strip() for p in args.protocols.split(",") if p.strip()]:
        base = Path(args.work) / protocol
        label = protocol if args.objective == "pointwise" else f"{protocol}, {args.objective}"
        runs = base if args.objective == "pointwise" else base / args.objective   # the set is shared
        if args.staged:
            runs, label = runs / "staged", label + ", staged"
        if args.grown:
            runs, label = runs / "grown", label + ", grown"
        if args.shrink and not args.cors_only:
            runs, label = runs / "shrink", label + ", shorter windows"
        data, out = base / "data", base / "campaign"
        t0, c0 = time.time(), time.process_time()
        fmu = set_fmu(data)
        gen = generate_set("recovery", data, numbers, workers=args.workers, protocol=protocol, progress=True,
                           log=lambda msg: print(msg, file=sys.stderr), fmu=fmu)
        gen_cpu = sum(r.get("cpu_s", 0.0) for r in gen if "cpu_s" in r)
        if args.cors_only or args.repeats > 1:
            for k in range(1, args.repeats):
                generate_set("recovery", base / f"data_r{k}", numbers, workers=args.workers, protocol=protocol,
                             progress=True, repeat=k, log=lambda msg: print(msg, file=sys.stderr), fmu=fmu)
            if args.repeats > 1:
                label += f", {args.repeats} records"
            folder = "cors_only" if args.cors_only else "ten_free"
            folder += "" if args.repeats == 1 else f"_k{args.repeats}"
            if args.grown and args.repeats > 1 and args.start != "complex":
                folder, label = folder + f"_{args.start}", label + f", started from {args.start}"
            if args.grown and args.halvings:
                folder, label = folder + f"_h{args.halvings}", label + f", {2 ** args.halvings} substeps"
            if args.grown and args.restarts:
                folder, label = folder + f"_r{args.restarts}", label + f", up to {args.restarts} restarts"
            if args.shrink and args.cors_only:
                folder, label = folder + "_shrink", label + ", shorter windows"
            results = joint_records(data, runs / folder, numbers, args, tare)
            cache = {r["measurement"]: r["f_truth"] for r in results}
            rows = rows_of(results, data, args.window, tare, cache, args.objective)
            label += " (CoRs only)" if args.cors_only else " (ten free)"
            # a table grows over several sessions (build/ is not kept): the stored rows of the
            # measurements not run this time stay
            kept = [q for q in (report["protocols"].get(label) or {}).get("rows", []) if q["number"] not in numbers]
            rows = sorted(kept + rows, key=lambda q: q["number"] or 0)
            entry = {"rows": rows, "summary": summary(rows), "wall_s": time.time() - t0}
            report["protocols"][label] = entry
            print(f"\n## {label}\n\n{table(rows)}\n\n{json.dumps(entry['summary'], indent=1)}")
            if args.json:
                write_json_atomic(args.json, report)
            continue
        # the campaign takes every measurement in the set's folder: the ones generated (--measurements)
        out = runs / "campaign"
        results = run_campaign(data, ["LW"], out, workers=args.workers, max_evals=args.max_evals, seed=args.seed,
                               window=args.window, tare=tare, presolve=args.presolve,
                               refine_evals=args.refine_evals, restarts=args.restarts, uncertainty=True,
                               progress=True, objective=args.objective, staged=args.staged,
                               shrink=args.shrink, grown=args.grown)
        cache = (report["protocols"].get(label) or {}).get("f_truth", {})
        results = [r for r in results if r.get("number") in numbers]
        rows = rows_of(results, data, args.window, tare, cache, args.objective)
        entry = {"rows": rows, "summary": summary(rows), "f_truth": cache, "wall_s": time.time() - t0,
                 "cpu_s_this_session": time.process_time() - c0, "generation_cpu_s": gen_cpu}
        report["protocols"][label] = entry
        print(f"\n## {label}\n\n{table(rows)}\n\n{json.dumps(entry['summary'], indent=1)}")
        if args.json:
            write_json_atomic(args.json, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
