#!/usr/bin/env python3
"""Where an identification's time goes: one default identification (the
front door, `identify_records` with the default Settings) of a recovery
measurement's start-stop records, its CPU split by pipeline stage and, within
each stage, into the C core's steps (fmi2DoStep), the starts (reset,
parameters, initialisation and the relaxation at rest, or the restore of a
kept relaxed chain) and Python (the stepping loop, interpolation, the
logger's filter, the objective, the optimisers, the journal), with the
simulations run and the seconds they simulated.

    .venv/bin/python benchmarks/profile_identification.py --measurements 20,1,9 \\
        --json benchmarks/results/profile_identification.json
    .venv/bin/python benchmarks/profile_identification.py --table --json benchmarks/results/profile_identification.json
    .venv/bin/python benchmarks/profile_identification.py --doc \
        --json benchmarks/results/profile_identification_before.json benchmarks/results/profile_identification.json
    .venv/bin/python benchmarks/profile_identification.py --ab sensitivities-ab \
        --json benchmarks/results/profile_sensitivities_before.json benchmarks/results/profile_sensitivities_after.json

The records are the recovery bench's (`--work`, made if missing). Stages are
found by wrapping the pipeline's stage functions for the run; a stage nested
in another (the refinement inside the shorter windows) is counted in the
innermost one and shown under its path. Nothing of the identification
changes: the profile's result is the front door's (its f and CoRs are
written beside the profile, the wrappers cost < 1 % of the CPU).
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_common import ROOT, hash_sources, write_between  # noqa: E402
from bench_recovery import set_fmu  # noqa: E402
from identification import Settings  # noqa: E402
from identification.pipeline.settings import load_settings  # noqa: E402
from identification.pipeline import (driver, growing, identify, identify_grown, windowing,  # noqa: E402
                                     edge_probe, joint_start)
from identification.objective.problem import IdentificationProblem  # noqa: E402
from lss_fmu import runner  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS, SYMBOL  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import generate_set, load_truth, parse_numbers  # noqa: E402

# (module, function, stage name): the pipeline's stages as its modules call them
STAGE_FUNCTIONS = [
    (identify_grown, "_once", "run"),
    (identify_grown, "single_start", "single start"),
    (growing, "fit_rest", "first window: rest fit"),
    (growing, "identify", "first window: complex"),
    (growing, "profile_polish", "first window: profile"),
    (growing, "_reset_unseen", "first window: unseen"),
    (growing, "_retried", "first window: retry"),
    (growing, "refine", "growing windows"),
    (identify_grown, "local_stage", "whole record"),
    (identify, "refine", "refinement"),
    (identify, "intervals", "intervals"),
    (identify_grown, "shrink_window", "shorter windows"),
    (windowing, "local_stage", "window"),
    (identify_grown, "_from_edges", "edge probes"),
    (edge_probe, "local_stage", "probe"),
]


class Profile:
    """Counters per stage path: CPU, core, starts, simulations, simulated s."""

    def __init__(self):
        self.stack = ["setup"]
        self.rows = defaultdict(lambda: defaultdict(float))
        self.mark = time.process_time()

    @property
    def path(self) -> str:
        return " / ".join(self.stack)

    def flush(self) -> None:
        now = time.process_time()
        self.rows[self.path]["cpu_s"] += now - self.mark
        self.mark = now

    def add(self, key: str, value: float) -> None:
        self.rows[self.path][key] += value

    @contextlib.contextmanager
    def stage(self, name: str):
        self.flush()
        self.stack.append(name)
        self.rows[self.path]["entered"] += 1
        try:
            yield
        finally:
            self.flush()
            self.stack.pop()


def instrument(prof: Profile) -> contextlib.ExitStack:
    """The stage functions, IdentificationProblem.run, ChainSimulator.start and
    the FMU's fmi2DoStep wrapped to count into `prof`, until the stack closes."""
    stack = contextlib.ExitStack()

    def patch(owner, name, new):
        old = getattr(owner, name)
        setattr(owner, name, new(old))
        stack.callback(setattr, owner, name, old)

    for module, fn, stage in STAGE_FUNCTIONS:
        def staged(old, stage=stage):
            @functools.wraps(old)
            def inner(*a, **k):
                with prof.stage(stage):
                    return old(*a, **k)
            return inner
        patch(module, fn, staged)

    def run(old):
        @functools.wraps(old)
        def inner(self, x, extra=None, channels=None, times=None, history=0.0):
            t = self.times if times is None else times
            prof.add("simulations", 1)
            prof.add("simulated_record_s", float(t[-1]) + float(history))
            kw = {} if channels is None else {"channels": channels}
            return old(self, x, extra, times=times, history=history, **kw)
        return inner
    patch(IdentificationProblem, "run", run)

    def start(old):
        @functools.wraps(old)
        def inner(self, params=None, tolerance=None, start_time=0.0):
            key = self._rest_key(dict(params or {}), tolerance, start_time)
            prof.add("relaxed" if key is not None and key not in self._rest else "restored", 1)
            t0 = time.process_time()
            try:
                return old(self, params, tolerance, start_time)
            finally:
                prof.add("start_cpu_s", time.process_time() - t0)
                _time_steps(self, prof)
        return inner
    patch(runner.ChainSimulator, "start", start)
    return stack


def _time_steps(sim, prof: Profile) -> None:
    """The instance's fmi2DoStep timed (once per FMU instance)."""
    funcs = getattr(sim.fmu, "_functions", {})
    raw = funcs.get("fmi2DoStep")
    if raw is None or getattr(raw, "_profiled", False):
        return
    clock = time.process_time   # CPU, not wall: a busy machine does not inflate it

    def do_step(*a):
        t0 = clock()
        try:
            return raw(*a)
        finally:
            prof.add("core_s", clock() - t0)
    do_step._profiled = True
    funcs["fmi2DoStep"] = do_step


def records_of(work: Path, number: int, repeats: int) -> list:
    base = work / "start-stop"
    fmu = set_fmu(base / "data")   # the set's FMU, as the recovery bench keeps it
    out = []
    for k in range(repeats):
        d = base / ("data" if k == 0 else f"data_r{k}")
        generate_set("recovery", d, [number], workers=1, protocol="start-stop", progress=False, repeat=k,
                     log=lambda msg: print(msg, file=sys.stderr), fmu=fmu)
        out.append(load_measurement(d / f"m{number:02d}"))
    return out


def profile_one(number: int, work: Path, repeats: int, settings: Settings) -> dict:
    records = records_of(work, number, repeats)
    prof = Profile()
    t0, c0 = time.time(), time.process_time()
    with instrument(prof):
        problem = driver.build_problem(records, "LW", settings)
        res = driver.identify_records(records, "LW", settings, problem=problem)
        prof.flush()
    cpu = time.process_time() - c0
    truth = load_truth(Path(records[0].path))
    stages = []
    for path, c in prof.rows.items():
        row = {"stage": path, **{k: float(v) for k, v in c.items()}}
        row["python_s"] = row.get("cpu_s", 0.0) - row.get("core_s", 0.0) - row.get("start_cpu_s", 0.0)
        stages.append(row)
    d = res.to_dict()
    return {"measurement": number, "layout": records[0].layout, "records": repeats,
            "carts": int(records[0].meta.get("n_carts") or 0) or None,
            "cpu_s": cpu, "wall_s": time.time() - t0, "nfev": int(res.nfev), "f": float(res.f),
            "window_s": float(res.problem.times[-1]),
            "cor_error": {SYMBOL[k]: d["values"][SYMBOL[k]] - truth["cor"][SYMBOL[k]] for k in CORS},
            "stages": stages}


def table(entry: dict) -> str:
    lines = []
    for m in entry["rows"]:
        lines.append(f"\n**{m['layout']}** (measurement {m['measurement']}, {m['records']} records, "
                     f"window {m['window_s']:.2g} s): {m['cpu_s']:.0f} CPU-s, {m['nfev']} evaluations\n")
        lines.append("| stage | CPU s | share | core s | starts s | Python s | simulations | simulated s | "
                     "CPU ms per simulated s |")
        lines.append("|" + "---|" * 9)
        for s in sorted(m["stages"], key=lambda s: -s.get("cpu_s", 0.0)):
            if s.get("cpu_s", 0.0) < 0.005 * m["cpu_s"]:
                continue
            sim_s = s.get("simulated_record_s", 0.0)
            per = f"{1e3 * s['cpu_s'] / sim_s:.0f}" if sim_s > 0 else ""
            lines.append(f"| {s['stage']} | {s['cpu_s']:.1f} | {100 * s['cpu_s'] / m['cpu_s']:.0f} % | "
                         f"{s.get('core_s', 0):.1f} | {s.get('start_cpu_s', 0):.1f} | {s['python_s']:.1f} | "
                         f"{s.get('simulations', 0):.0f} | {sim_s:.0f} | {per} |")
        tot = {k: sum(s.get(k, 0.0) for s in m["stages"]) for k in
               ("core_s", "start_cpu_s", "python_s", "simulations", "simulated_record_s")}
        lines.append(f"| **all** | {m['cpu_s']:.1f} | 100 % | {tot['core_s']:.1f} | {tot['start_cpu_s']:.1f} | "
                     f"{tot['python_s']:.1f} | {tot['simulations']:.0f} | {tot['simulated_record_s']:.0f} | "
                     f"{1e3 * m['cpu_s'] / max(tot['simulated_record_s'], 1e-9):.0f} |")
    return "\n".join(lines)


def ab_table(before: dict, after: dict, unit: str = "cpu") -> str:
    """Two profiles of the same measurements side by side: CPU-s with their ratio, the
    stages that changed most, f and the largest CoR error (e_JA, e_SW, e_RW). `unit`
    "record-s": the stages in simulated record-seconds (the machine-independent cost)
    instead of CPU-s, with the intervals and the total beside the CPU."""
    key = {"cpu": "cpu_s", "record-s": "simulated_record_s"}[unit]
    names = ["growing windows", "whole record / refinement", "first window: profile"]
    heads = ["growing windows", "whole-record refinement", "first window: profile"]
    if unit == "record-s":
        names.insert(2, "whole record / intervals")
        heads.insert(2, "intervals")
    total = ["simulated record-s, before -> after"] if unit == "record-s" else []
    out = ["| measurement (layout) | CPU-s, before -> after | " + "".join(f"{t} | " for t in total)
           + "first window: rest fit + complex | " + " | ".join(heads) + " | f, before -> after | "
           "largest error of e_JA, e_SW, e_RW |",
           "|---|---|" + "---|" * (len(total) + 1 + len(heads)) + "---|---|"]
    old = {m["measurement"]: m for m in before["rows"]}

    def stage(m, name):   # a stage nested in the rest fit counts as the rest fit's
        return sum(s.get(key, 0.0) for s in m["stages"] if (name in s["stage"] if name == "rest fit" else
                                                             s["stage"].endswith(name) and "rest fit" not in s["stage"]))

    def simulated(m):
        return sum(s.get("simulated_record_s", 0.0) for s in m["stages"])

    def worst(m):
        return max(abs(m["cor_error"][k]) for k in ("e_JA", "e_SW", "e_RW"))
    for b in after["rows"]:
        a = old.get(b["measurement"])
        if a is None:
            continue
        cells = [f"{simulated(a):.0f} -> {simulated(b):.0f} ({simulated(b) / simulated(a):.2f})"] if total else []
        cells += [f"{stage(a, 'rest fit') + stage(a, 'complex'):.0f} -> "
                  f"{stage(b, 'rest fit') + stage(b, 'complex'):.0f}"]
        cells += [f"{stage(a, n):.0f} -> {stage(b, n):.0f}" for n in names]
        out.append(f"| {b['measurement']} ({b['layout'].replace('layout', '')}) | {a['cpu_s']:.0f} -> "
                   f"{b['cpu_s']:.0f} ({b['cpu_s'] / a['cpu_s']:.2f}) | {' | '.join(cells)} | "
                   f"{a['f']:.4f} -> {b['f']:.4f} | {worst(a):.4f} -> {worst(b):.4f} |")
    if total:
        pairs = [(old[b["measurement"]], b) for b in after["rows"] if b["measurement"] in old]
        sa, sb = sum(simulated(a) for a, _ in pairs), sum(simulated(b) for _, b in pairs)
        ca, cb = sum(a["cpu_s"] for a, _ in pairs), sum(b["cpu_s"] for _, b in pairs)
        out.append(f"| all {len(pairs)} | {ca:.0f} -> {cb:.0f} ({cb / ca:.2f}) | {sa:.0f} -> {sb:.0f} ({sb / sa:.2f}) |"
                   + " |" * (3 + len(heads)))
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--measurements", default="20,1,9", help="recovery measurements (default: layouts 7, 1, 3)")
    ap.add_argument("--work", default="build/bench_recovery")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", nargs="+", default=None, help="the profile's file (--doc: before and after)")
    ap.add_argument("--settings", default=None, help="an expert's settings file (default: the defaults)")
    ap.add_argument("--table", action="store_true", help="print the Markdown tables of --json and stop")
    ap.add_argument("--doc", action="store_true", help="write the tables of the --json files (before, after) into "
                    "docs/benchmarks.md and stop")
    ap.add_argument("--ab", metavar="TAG", default=None, help="write the side-by-side table of the two --json "
                    "files (before, after) between docs/benchmarks.md's TAG markers and stop")
    ap.add_argument("--ab-unit", choices=("cpu", "record-s"), default="cpu",
                    help="--ab's stages in CPU-s or in simulated record-seconds (with the intervals and the total)")
    args = ap.parse_args(argv)
    if args.ab:
        before, after = (json.loads(Path(j).read_text()) for j in args.json)
        write_between(ROOT / "docs" / "benchmarks.md", args.ab, ab_table(before, after, args.ab_unit))
        return 0
    if args.table or args.doc:
        texts = [table(json.loads(Path(j).read_text())) for j in args.json]
        if not args.doc:
            print("\n".join(texts))
            return 0
        heads = ["#### Before", "#### After"] if len(texts) == 2 else [""] * len(texts)
        write_between(ROOT / "docs" / "benchmarks.md", "profile",
                      "\n".join(f"{h}\n{t}\n" for h, t in zip(heads, texts)))
        return 0
    args.json = args.json[0] if args.json else None
    settings = load_settings(args.settings)
    old = json.loads(Path(args.json).read_text()) if args.json and Path(args.json).exists() else {}
    numbers = parse_numbers(args.measurements)
    if old and old.get("settings") != settings.to_dict():
        raise SystemExit(f"{args.json}: a profile of other settings; give another --json")
    rows = {m["measurement"]: m for m in old.get("rows", []) if m["measurement"] not in numbers}
    stamp = hash_sources(__import__("hashlib").sha256()).hexdigest()[:12]
    for n in numbers:
        row = profile_one(n, Path(args.work), args.repeats, settings)
        row["code"] = stamp
        rows[n] = row
        print(f"measurement {n}: {row['cpu_s']:.0f} CPU-s, {row['nfev']} evaluations", file=sys.stderr)
        if args.json:
            write_json_atomic(args.json, {"command": " ".join(sys.argv), "settings": settings.to_dict(),
                                          "rows": list(rows.values())})
    if args.json:
        print(table(json.loads(Path(args.json).read_text())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
