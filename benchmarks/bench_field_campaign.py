#!/usr/bin/env python3
"""The paper's study through the product: the field set through `lss campaign`
and `lss report`, in both conditions (issue 51).

The field set (`lss rig --set field`) is made with the GZ law, as-built
tracks, a mass spread and a guide gap, none of which the candidate laws or the
design drawing have (docs/measurements.md), as for a real sorter. Each
measurement is recorded `--repeats` times from rest (start-stop, the chain
parked elsewhere each time: `lss rig --repeat K`), and every sorter is
identified jointly under every law (the paper's four and GZ, the control that
must reach the noise) with the front door's defaults, ten design variables
free:

- `design`: on the design drawing, what a user has;
- `surveyed`: with each sorter's survey given to the FMU (`--surveyed`: the
  as-built track, the carts' mass, the guide gap).

Then `lss report` for each, and a summary (per law the median f, the tests,
the cost) in the JSON.

    .venv/bin/python benchmarks/bench_field_campaign.py --json benchmarks/results/field_campaign.json

The records are made once and reused; each campaign writes every result
atomically and journals every evaluation, so the benchmark can be stopped and
started again (the wall time, CPU and evaluations of each session are kept in
the JSON).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from identification.pipeline.campaign import run_campaign  # noqa: E402
from identification.pipeline.settings import load_settings  # noqa: E402
from identification.pipeline.stats import load_results, model_tests  # noqa: E402
from lss_app.campaign_report import write_report  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.rig import generate_set, parse_numbers  # noqa: E402



def _cpu() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _journaled(out: Path) -> int:
    """Evaluations in the campaign's journals (each is one simulation)."""
    return sum(sum(1 for line in j.read_text().splitlines() if line.strip())
               for j in (out / "journals").glob("*.jsonl")) if (out / "journals").is_dir() else 0


def summarise(out: Path, results: list, models: list) -> dict:
    """Per law the final f (median, IQR, range) and the tests of the report."""
    df = load_results(out)
    nfev = np.array([r["nfev"] for r in results])
    per_model = {}
    for m in models:
        f = df.loc[df["model"] == m, "f"].to_numpy(float)
        if not f.size:
            continue
        q1, med, q3 = np.percentile(f, [25, 50, 75])
        per_model[m] = {"n": int(f.size), "f_median": float(med), "f_iqr": float(q3 - q1),
                        "f_min": float(f.min()), "f_max": float(f.max())}
    cpu = [r.get("cpu_s") or 0.0 for r in results]
    return {"per_model": per_model, "tests": model_tests(df),
            "evaluations": {"median": float(np.median(nfev)), "min": int(nfev.min()), "max": int(nfev.max())},
            "cpu_s": {"total": float(sum(cpu)), "median": float(np.median(cpu))}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="build/bench_field_campaign")
    ap.add_argument("--models", default="HC,HW,LW,LN,GZ")
    ap.add_argument("--conditions", default="design,surveyed", help="design, surveyed or both")
    ap.add_argument("--measurements", default="1-22")
    ap.add_argument("--protocol", default="start-stop")
    ap.add_argument("--repeats", type=int, default=3, help="records per sorter, identified jointly")
    ap.add_argument("--settings", default=None, help="an expert's settings file (identification.pipeline.settings)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    conditions = [c for c in args.conditions.split(",") if c]
    bad = sorted(set(conditions) - {"design", "surveyed"})
    if bad:
        raise SystemExit(f"--conditions: {bad[0]!r} is neither design nor surveyed")
    work = Path(args.work) / args.protocol
    numbers = parse_numbers(args.measurements)
    dirs = [work / ("field" if k == 0 else f"field_r{k}") for k in range(args.repeats)]
    for k, d in enumerate(dirs):   # made once, then reused
        generate_set("field", d, numbers, workers=args.workers, protocol=args.protocol, repeat=k, progress=False,
                     log=lambda msg: print(msg, file=sys.stderr))
    models = [m for m in args.models.split(",") if m]
    settings = load_settings(args.settings)
    old = json.loads(Path(args.json).read_text()) if args.json and Path(args.json).is_file() else {}
    if old and old.get("identify") != settings.to_dict():
        old = {}   # another method: its sessions are not this one's
    summary = {"settings": {"models": models, "protocol": args.protocol, "repeats": args.repeats,
                            "measurements": args.measurements, "workers": args.workers},
               "identify": settings.to_dict(), "conditions": {}}
    for cond in conditions:
        out = work / f"campaign_{cond}"
        before = _journaled(out)
        w0, c0 = time.perf_counter(), _cpu()
        results = run_campaign(dirs, models, out, settings=settings, workers=args.workers, progress=True,
                               surveyed=cond == "surveyed")
        session = {"wall_s": time.perf_counter() - w0, "cpu_s": _cpu() - c0,
                   "evaluations": _journaled(out) - before}
        report = write_report(out)
        kept = (old.get("conditions") or {}).get(cond, {}).get("sessions", [])
        summary["conditions"][cond] = {**summarise(out, results, models), "report": str(report),
                                       "sessions": kept + [session]}
        for m, v in summary["conditions"][cond]["per_model"].items():
            print(f"{cond} {m}: final f median {v['f_median']:.4g}, IQR {v['f_iqr']:.4g}, range "
                  f"{v['f_min']:.4g}-{v['f_max']:.4g} ({v['n']} sorters)")
        print(f"{cond}: report {report}; this session {session['wall_s']:.0f} s wall, {session['cpu_s']:.0f} s CPU")
        if args.json:
            write_json_atomic(Path(args.json), summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
