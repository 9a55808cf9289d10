#!/usr/bin/env python3
"""Turns the JSON results of the speed benchmarks into the tables of
docs/benchmarks.md (between the markers <!-- tables:begin --> and
<!-- tables:end -->; the prose around them is kept).

Usage::

    .venv/bin/python benchmarks/bench_report.py            # reads benchmarks/results/*.json
    .venv/bin/python benchmarks/bench_report.py --print    # tables to stdout only

Expected files in benchmarks/results/: {before,after}_throughput.json
(bench_throughput.py), {before,after}_fmpy.json (bench_fmpy.py),
{before,after}_memory.json (bench_memory.py); missing ones are skipped.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from bench_common import write_between

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
DOC = HERE.parent / "docs" / "benchmarks.md"


def load(name):
    p = RESULTS / f"{name}.json"
    return json.loads(p.read_text()) if p.exists() else None


def pct(x):
    return f"{100 * x:.2f} %"


def throughput_table(before, after) -> list[str]:
    rows = ["| layout | carts | version | tol | cart-s per CPU-s | speed-up | steps/s | rhs/s | ns per cart and rhs "
            "| NRMSD restart (0.5 s) | NRMSD free run |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    base = {(r["layout"], r["tol"]): r for r in (before or {}).get("results", [])}
    for label, data in (("before", before), ("after", after)):
        for r in (data or {}).get("results", []):
            b = base.get((r["layout"], 1e-4))
            sp = f"{r['throughput'] / b['throughput']:.2f}x" if (b and label == "after") else ""
            rows.append(f"| {r['layout']} | {r['carts']} | {label} | {r['tol']:.0e} | {r['throughput']:.0f} | {sp} | "
                        f"{r['steps_per_s']:.0f} | {r['rhs_per_s']:.0f} | {r['ns_per_cart_rhs']:.0f} | "
                        f"{pct(r['nrmsd_restart_max'])} | {pct(r['nrmsd_free_max'])} |")
    return rows


def scaling_table(before, after) -> list[str]:
    rows = ["| version | tol | exponent b (CPU ~ carts^b) | CPU per cart-second, ms (52 / 171 / 685 carts) "
            "| spread (max/min - 1) |", "|---|---|---|---|---|"]
    for label, data in (("before", before), ("after", after)):
        for tol, sc in (data or {}).get("scaling", {}).items():
            rows.append(f"| {label} | {float(tol):.0e} | {sc['exponent']:.3f} | "
                        f"{' / '.join(f'{1e3 * x:.2f}' for x in sc['cost_per_cart_s'])} | {pct(sc['spread'])} |")
    return rows


def mix_table(before, after) -> list[str]:
    rows = ["| version | layout | carts | cart-s per CPU-s | steps/s | ns per cart and rhs | CPU per cart-second, ms |",
            "|---|---|---|---|---|---|---|"]
    for label, data in (("before", before), ("after", after)):
        mix = (data or {}).get("mix")
        if not mix:
            continue
        for r in mix["results"]:
            rows.append(f"| {label} | {r['layout']} | {r['carts']} | {r['throughput']:.0f} | {r['steps_per_s']:.0f} | "
                        f"{r['ns_per_cart_rhs']:.0f} | {1e3 * r['cpu'] / r['window'] / r['carts']:.2f} |")
        sc = mix["scaling"]
        rows.append(f"| {label} | exponent b | | | | | {sc['exponent']:.3f} (spread {pct(sc['spread'])}) |")
    return rows


def fmpy_table(before, after) -> list[str]:
    rows = ["| version | fmpy run, CPU s | C master loop, CPU s | difference | master loop alone, us/point "
            "(runner / fmpy wrappers) | core work, us/point | loop overhead | layout-7 lap CPU s | "
            "evaluations per hour |", "|---|---|---|---|---|---|---|---|---|"]
    for label, r in (("before", before), ("after", after)):
        if not r:
            continue
        lap = f"{r['lap_cpu']:.2f} | {r['evals_per_hour']:.0f}" if "lap_cpu" in r else " | "
        loop = (f"{r['loop_us_raw']:.2f} / {r['loop_us_fmpy']:.2f} | {r['core_us_per_point']:.0f} | "
                f"{pct(r['loop_overhead'])}") if "loop_us_raw" in r else " | | "
        rows.append(f"| {label} | {r['cpu_fmpy']:.3f} | {r['cpu_core']:.3f} | {pct(r['overhead'])} | {loop} | {lap} |")
    return rows


def memory_table(before, after) -> list[str]:
    rows = ["| version | layout7 instance | layout1 instance | layout3 instance | cycles | held bytes, first -> last "
            "| growth | RSS, first -> last cycle |", "|---|---|---|---|---|---|---|---|"]
    for label, r in (("before", before), ("after", after)):
        if not r:
            continue
        ib = r["instance_bytes"]
        kib = [f"{ib[k]['bytes'] / 1024:.0f} KiB" if k in ib else "" for k in ("layout7", "layout1", "layout3")]
        first, last = r["trace"][0], r["trace"][-1]
        rows.append(f"| {label} | {' | '.join(kib)} | {r['cycles']} | {first[1]} -> {last[1]} | "
                    f"{r['growth_bytes']} B | {first[3]} -> {last[3]} KiB |")
    return rows


def tables() -> str:
    out = []
    bt, at = load("before_throughput"), load("after_throughput")
    if bt or at:
        m = (at or bt)["machine"]
        out += [f"Machine: {m}", "", "### Throughput and accuracy", ""] + throughput_table(bt, at)
        out += ["", "### Scaling with the number of carts", ""] + scaling_table(bt, at)
    bx, ax = load("before_mix"), load("after_mix")
    if bx or ax:
        out += ["", "### Scaling at a fixed track mix (layout 7 repeated k times, pretension k x 0.01 m)", ""]
        out += mix_table(bx, ax)
    bf, af = load("before_fmpy"), load("after_fmpy")
    if bf or af:
        out += ["", "### fmpy at 300 Hz against the C core, and identification speed", ""] + fmpy_table(bf, af)
    bm, am = load("before_memory"), load("after_memory")
    if bm or am:
        out += ["", "### Memory", ""] + memory_table(bm, am)
    return "\n".join(out) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--print", action="store_true")
    a = ap.parse_args(argv)
    t = tables()
    if a.print or not DOC.exists():
        print(t)
        return
    write_between(DOC, "tables", t)
    print(f"wrote the tables into {DOC}")


if __name__ == "__main__":
    main()
