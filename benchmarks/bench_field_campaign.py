#!/usr/bin/env python3
"""The whole field set through the campaign (issue 6): wall time, evaluations,
and whether the paper's section-4 verdict comes out.

22 measurements x the contact models through `lss campaign`'s pipeline (the
front door's method for the records: the force statistics for the field
set's steady running, all ten design variables free), on local worker
processes, then `lss report`. The field set's truth is the GZ law, which none
of the candidates is (docs/measurements.md), as for a real sorter. An
expert's settings file changes the pipeline (`--settings`, as lss campaign).

    .venv/bin/python benchmarks/bench_field_campaign.py --json benchmarks/results/field_campaign.json

The measurements are made once with a shortened record (--lap-seconds) and
reused; the campaign writes every result atomically and journals every
evaluation, so the benchmark can be stopped and started again (the wall time
of each session and the evaluations it simulated are kept in the JSON).
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
from lss_fmu.rig import generate_set  # noqa: E402



def _cpu() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _journaled(out: Path) -> int:
    """Evaluations in the campaign's journals (each is one simulation)."""
    return sum(sum(1 for line in j.read_text().splitlines() if line.strip())
               for j in (out / "journals").glob("*.jsonl")) if (out / "journals").is_dir() else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="build/bench_field_campaign")
    ap.add_argument("--models", default="HC,HW,LW,LN")
    ap.add_argument("--lap-seconds", type=float, default=2.0)
    ap.add_argument("--settings", default=None, help="an expert's settings file (identification.pipeline.settings)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    work = Path(args.work)
    data, out = work / "field", work / "campaign"
    if not (data / "set.json").is_file():  # made once, then reused
        generate_set("field", data, None, workers=args.workers, lap_seconds=args.lap_seconds, progress=False)
    models = [m for m in args.models.split(",") if m]
    old = json.loads(Path(args.json).read_text()) if args.json and Path(args.json).is_file() else {}
    settings = load_settings(args.settings)
    sessions = old.get("sessions", []) if old.get("identify") == settings.to_dict() else []
    before = _journaled(out)
    w0, c0 = time.perf_counter(), _cpu()
    results = run_campaign([data], models, out, settings=settings, workers=args.workers, progress=True)
    wall, cpu = time.perf_counter() - w0, _cpu() - c0
    done_now = _journaled(out) - before
    report = write_report(out)
    df = load_results(out)
    tests = model_tests(df)
    nfev = np.array([r["nfev"] for r in results])
    per_model = {}
    for m in models:
        f = df.loc[df["model"] == m, "f"].to_numpy(float)
        q1, med, q3 = np.percentile(f, [25, 50, 75])
        per_model[m] = {"n": int(f.size), "f_median": float(med), "f_iqr": float(q3 - q1),
                        "f_min": float(f.min()), "f_max": float(f.max())}
    summary = {
        "settings": {"models": models, "lap_seconds": args.lap_seconds, "workers": args.workers,
                     "measurements": len({r["sorter"] for r in results})},
        "identify": settings.to_dict(),
        "sessions": sessions + [{"wall_s": wall, "cpu_s": cpu, "evaluations": done_now}],
        "evaluations": {"median": float(np.median(nfev)), "min": int(nfev.min()), "max": int(nfev.max())},
        "per_model": per_model, "tests": tests, "report": str(report),
    }
    for m, v in per_model.items():
        print(f"{m}: final f median {v['f_median']:.4g}, IQR {v['f_iqr']:.4g}, range "
              f"{v['f_min']:.4g}-{v['f_max']:.4g} ({v['n']} measurements)")
    print(f"ANOVA p = {tests['anova_p']:.3g}, Kruskal-Wallis p = {tests['kruskal_p']:.3g}; "
          f"evaluations per identification {summary['evaluations']}; this run {wall:.0f} s wall, {cpu:.0f} s CPU")
    print(f"report: {report}")
    if args.json:
        write_json_atomic(Path(args.json), summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
