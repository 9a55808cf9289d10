#!/usr/bin/env python3
"""The same identifications and closed loops on every code path the machine offers.

A result that changes with the CPU's rounding is not a result. Each case runs
once per configuration, each configuration in a process of its own:

- the FMU's right-hand side forced onto one vector path (`solver.vector_path`
  1 scalar, 2 AVX2, 3 AVX-512), numpy's BLAS as the machine picks it;
- the widest path, numpy's BLAS forced onto another kernel (OPENBLAS_CORETYPE:
  Haswell, Sandybridge): the last digits of every linear solve and matrix
  product of the identification change, as they do on another CPU.

The records are made once, before any configuration runs, so every
configuration fits the same data. The cases:

- `identify_mNN`: the recovery set's start-stop record NN (lss rig), its first
  1.5 s, LW, the ten design variables free, the front door with its defaults
  (`identify_records`, as `lss identify REC --model LW` runs it, the window
  1.5 s);
- `pointwise_release`: for comparison, the paper's pointwise objective (not
  the default) on the release transient's first 0.6 s, four CoRs free,
  Complex-RF and Levenberg-Marquardt with intervals;
- `loop_clean`, `loop_mass`: the closed loop on a clean release transient and
  on one with the transducer cart a quarter heavier (the close-loop tests'
  cases and budgets).

    .venv/bin/python benchmarks/bench_cross_path.py run       # resumes: a stored row is kept
    .venv/bin/python benchmarks/bench_cross_path.py report    # table into docs/robustness.md

Rows are stored in benchmarks/results/cross_path.json, written atomically
after each, each stamped with a hash of what decides it (the sources of
identification/, lss_fmu/ and fmu_src/, and this file's cases and budgets);
`run` reruns a row of another stamp, `report` says how many rows are of the
current code.
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import inspect
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_common import ROOT, code_version, hash_sources, machine  # noqa: E402  (sets one BLAS thread)

import numpy as np  # noqa: E402

from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "cross_path.json"
WORK = ROOT / "build" / "cross_path"
DOC = ROOT / "docs" / "robustness.md"
BEGIN, END = "<!-- cross-path table: begin -->", "<!-- cross-path table: end -->"

CONFIGS = {   # name -> (solver.vector_path, OPENBLAS_CORETYPE or None: the machine's choice)
    "scalar": (1, None),
    "avx2": (2, None),
    "avx512": (3, None),
    "auto+Haswell": (0, "Haswell"),         # the widest path, another BLAS kernel
    "auto+Sandybridge": (0, "Sandybridge"),
}
REFERENCE = "scalar"   # every machine has it
WINDOW = 1.5           # s of the rig records identified
CASES = {
    "identify_m20": dict(kind="identify", number=20),   # layout 7
    "identify_m01": dict(kind="identify", number=1),    # layout 1
    "pointwise_release": dict(kind="pointwise"),         # not the default method: for comparison
    "loop_clean": dict(kind="loop", seed=3, transducer=20, params={}),
    "loop_mass": dict(kind="loop", seed=146954997, transducer=7,
                      params={"effects.mass.transducer_factor": 1.25},
                      extra=dict(fit_evals=20, base_refine_evals=60, candidates=4)),
}
LOOP_BUDGET = dict(base_evals=80, max_evals=100, refine_evals=40)


def code_stamp() -> str:
    """A short hash of the model's and the identification's sources and of this file's cases and budgets."""
    h = hash_sources(hashlib.sha256())
    for fn in (make_records, run_identify, run_pointwise, run_loop):
        h.update(inspect.getsource(fn).encode())
    h.update(repr((CONFIGS, CASES, LOOP_BUDGET, front_door_settings().to_dict(), WINDOW)).encode())
    return h.hexdigest()[:12]


def record_dir(number: int) -> Path:
    from lss_fmu.rig import folder_name
    return WORK / "records" / folder_name(number)


def make_records() -> None:
    from lss_fmu.rig import run_measurement
    from lss_fmu.runner import ChainSimulator
    for case in CASES.values():
        if case["kind"] == "identify" and not record_dir(case["number"]).is_dir():
            with ChainSimulator() as s:
                run_measurement("recovery", case["number"], WORK / "records", s, protocol="start-stop",
                                lap_seconds=WINDOW + 0.2)


def path_used(path: int) -> int:
    from lss_fmu.runner import ChainSimulator
    with ChainSimulator() as s:
        s.start({"layout.name": "demo", "solver.vector_path": path})
        return int(s.get("solver.vector_path_used"))


def front_door_settings():
    from identification import Settings
    return Settings(window=WINDOW)


def run_identify(case: dict, path: int) -> dict:
    from identification import build_problem, identify_records
    from lss_fmu.measurement import load_measurement
    from lss_fmu.rig import load_truth, true_design_values
    meas = load_measurement(record_dir(case["number"]))
    settings = front_door_settings()
    p = build_problem([meas], "LW", settings)
    p = dataclasses.replace(p, fixed={**p.fixed, "solver.vector_path": path})
    truth = true_design_values(load_truth(meas))
    f_truth = float(p(np.array([truth[n] for n in p.free])))
    res = identify_records([meas], "LW", settings, seed=0, problem=p)
    iv = {i.name: i for i in (res.intervals or [])}
    return {"f": float(res.f), "f_truth": f_truth, "nfev": int(res.nfev),
            "x": {n: float(v) for n, v in zip(p.free, res.x)},
            "truth": {n: truth[n] for n in CORS},
            "intervals": {n: iv[n].to_dict() for n in CORS if n in iv}}


def run_pointwise(case: dict, path: int) -> dict:
    """The paper's pointwise objective on the release transient's first 0.6 s
    (identification.loop.synthetic), four CoRs free: Complex-RF, Levenberg-Marquardt,
    intervals (identification.pipeline.identify)."""
    from identification.pipeline.identify import identify
    from identification.loop.synthetic import TRUTH, release_problem
    base = release_problem(window=0.6)
    p = dataclasses.replace(base, fixed={**base.fixed, "solver.vector_path": path})
    res = identify(p, max_evals=150, refine_evals=200, uncertainty=True, seed=0, progress=False)
    iv = {i.name: i for i in (res.intervals or [])}
    truth = np.array([TRUTH[n] for n in CORS])
    return {"f": float(res.f), "f_truth": float(p(truth)), "nfev": int(res.nfev),
            "x": {n: float(v) for n, v in zip(p.free, res.x)}, "truth": {n: TRUTH[n] for n in CORS},
            "intervals": {n: iv[n].to_dict() for n in CORS if n in iv}}


def run_loop(case: dict, path: int) -> dict:
    from identification.loop.close_loop import close_loop
    from identification.loop.settings import LoopSettings
    from identification.loop.synthetic import effect_case
    problem, _ = effect_case([], case["seed"], params=dict(case["params"]), transducer=case["transducer"])
    problem.fixed["solver.vector_path"] = path
    res = close_loop(problem, rounds=1, seed=0, settings=LoopSettings(**LOOP_BUDGET, **case.get("extra", {})))
    rnd = res.rounds[0]
    return {"found": res.found, "outcome": res.outcome,
            "amplitude": float(rnd.amplitude) if rnd.confirmed else None,
            "f_base": float(rnd.f_base), "f_extended": None if rnd.f_extended is None else float(rnd.f_extended)}


def one(case_name: str, config: str) -> dict:
    """One case on one configuration, in this process (its BLAS set by the caller's environment)."""
    import threadpoolctl
    path, _ = CONFIGS[config]
    used = path_used(path)
    blas = sorted({i.get("architecture", "?") for i in threadpoolctl.threadpool_info()
                   if i.get("user_api") == "blas"})
    row = {"case": case_name, "config": config, "vector_path_used": used, "blas": blas,
           "code": code_version(), "stamp": code_stamp()}
    if path and used != path:
        return {**row, "skipped": "this CPU or build has no such path"}
    case = CASES[case_name]
    c0 = time.process_time()
    run_case = {"identify": run_identify, "pointwise": run_pointwise, "loop": run_loop}[case["kind"]]
    row.update(run_case(case, path))
    row["cpu_s"] = time.process_time() - c0
    return row


def load_rows() -> dict:
    if not RESULTS.is_file():
        return {"machine": machine(), "rows": []}
    return json.loads(RESULTS.read_text())


def run(cases, configs, jobs: int) -> None:
    make_records()
    data = load_rows()
    stamp = code_stamp()
    done = {(r["case"], r["config"]) for r in data["rows"] if r.get("stamp") == stamp}
    todo = [(c, k) for c in cases for k in configs if (c, k) not in done]
    running = []

    def collect(block: bool):
        for item in list(running):
            proc, c, k = item
            if proc.poll() is None and not block:
                continue
            out, err = proc.communicate()
            running.remove(item)
            if proc.returncode != 0:
                print(f"{c} / {k}: failed\n{err[-2000:]}", file=sys.stderr)
                continue
            row = json.loads(out.strip().splitlines()[-1])
            data["rows"] = [r for r in data["rows"] if (r["case"], r["config"]) != (c, k)] + [row]
            data["machine"] = machine()
            write_json_atomic(RESULTS, data)
            print(f"{c} / {k}: {summary_of(row)} ({row.get('cpu_s', 0):.0f} CPU-s)", flush=True)

    for c, k in todo:
        while len(running) >= jobs:
            collect(block=False)
            time.sleep(1.0)
        env = dict(os.environ)
        blas = CONFIGS[k][1]
        env.pop("OPENBLAS_CORETYPE", None)
        if blas:
            env["OPENBLAS_CORETYPE"] = blas
        proc = subprocess.Popen([sys.executable, __file__, "one", c, k], env=env, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        running.append((proc, c, k))
    while running:
        collect(block=True)


def summary_of(row: dict) -> str:
    if "skipped" in row:
        return row["skipped"]
    if "x" in row:
        off = max(abs(row["x"][n] - row["truth"][n]) for n in ("contact.e_JA", "contact.e_SW", "contact.e_RW"))
        return " ".join(f"{n.split('.')[-1]} {row['x'][n]:.3f}" for n in CORS) + \
            f" (e_JA, e_SW, e_RW at most {off:.3f} off the truth), f/f(truth) {row['f'] / row['f_truth']:.3f}"
    amp = f", amplitude {row['amplitude']:.3f}" if row.get("amplitude") is not None else ""
    return f"{row['outcome']}{amp}"


def compare(rows: list) -> dict:
    """Per case: each configuration against the reference (scalar path): the
    CoRs' shift as a fraction of the reference interval's half-width, whether
    each CoR is claimed the same way, the verdict."""
    out = {}
    by_case = {}
    for r in rows:
        if "skipped" not in r:
            by_case.setdefault(r["case"], {})[r["config"]] = r
    for case, rs in by_case.items():
        ref = rs.get(REFERENCE)
        if ref is None:
            continue
        cmp = {}
        for k, r in rs.items():
            if "x" in r:
                frac, same_claim = {}, True
                for n in CORS:
                    iv = ref["intervals"].get(n)
                    half = 0.5 * (iv["upper"] - iv["lower"]) if iv else float("nan")
                    frac[n] = abs(r["x"][n] - ref["x"][n]) / half if half > 0 else float("nan")
                    same_claim &= (iv or {}).get("identifiable") == (r["intervals"].get(n) or {}).get("identifiable")
                cmp[k] = {"shift_over_halfwidth": frac, "same_claims": bool(same_claim),
                          "f_ratio": r["f"] / ref["f"]}
            else:
                cmp[k] = {"same_verdict": (r["found"], r["outcome"]) == (ref["found"], ref["outcome"])}
        out[case] = cmp
    return out


def table(data: dict) -> str:
    stamp = code_stamp()
    every = data["rows"]
    rows = sorted((r for r in every if r.get("stamp") == stamp),
                  key=lambda r: (r["case"], list(CONFIGS).index(r["config"])))
    cmp = compare(rows)
    lines = [f"Machine: {data.get('machine', '?')}. {len(rows)} of {len(every)} stored rows of the current code "
             f"(stamp {stamp}; commit {', '.join(sorted({r.get('code', '?') for r in rows})) or '-'}), the others "
             f"left out. Reference: the {REFERENCE} path.", "",
             "| case | configuration | BLAS kernel | result | against the reference | CPU-s |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        c = cmp.get(r["case"], {}).get(r["config"], {})
        if "skipped" in r:
            against = "-"
        elif "shift_over_halfwidth" in c:
            worst = max(c["shift_over_halfwidth"].values())
            against = (f"largest CoR shift {worst:.2f} of a half-interval, claims "
                       f"{'the same' if c['same_claims'] else 'differ'}, f x {c['f_ratio']:.3f}")
        else:
            against = "same verdict" if c.get("same_verdict") else "**verdict differs**"
        lines.append(f"| {r['case']} | {r['config']} | {', '.join(r.get('blas', []))} | {summary_of(r)} | "
                     f"{against} | {r.get('cpu_s', 0):.0f} |")
    return "\n".join(lines)


def report() -> int:
    data = load_rows()
    text = table(data)
    print(text)
    doc = DOC.read_text()
    if BEGIN in doc and END in doc:
        head, rest = doc.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        DOC.write_text(f"{head}{BEGIN}\n{text}\n{END}{tail}")
    else:
        print(f"{DOC} has no {BEGIN} ... {END} block: table not written there", file=sys.stderr)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the missing rows (each case x configuration in a process)")
    r.add_argument("--cases", default=",".join(CASES), help="comma-separated, of: " + ", ".join(CASES))
    r.add_argument("--configs", default=",".join(CONFIGS), help="comma-separated, of: " + ", ".join(CONFIGS))
    r.add_argument("--jobs", type=int, default=2, help="processes at once (default 2)")
    o = sub.add_parser("one", help="one case on one configuration; prints its row as JSON")
    o.add_argument("case", choices=list(CASES))
    o.add_argument("config", choices=list(CONFIGS))
    sub.add_parser("report", help="the table, also written into docs/robustness.md")
    a = ap.parse_args(argv)
    if a.cmd == "one":
        print(json.dumps(one(a.case, a.config)))
        return 0
    if a.cmd == "report":
        return report()
    cases = [c for c in a.cases.split(",") if c]
    configs = [c for c in a.configs.split(",") if c]
    for c in cases:
        if c not in CASES:
            ap.error(f"unknown case {c!r}: use {', '.join(CASES)}")
    for k in configs:
        if k not in CONFIGS:
            ap.error(f"unknown configuration {k!r}: use {', '.join(CONFIGS)}")
    if a.jobs < 1:
        ap.error("--jobs must be at least 1")
    run(cases, configs, a.jobs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
