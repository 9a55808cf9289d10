"""`lss layouts ...`: Table 2 as measured, the closure checker, the drawings,
and the generator of the built-in layout files.

    lss layouts                          Table 2 measured from the built-in files
    lss layouts check FILE|NAME ...      closure in position and direction (exit 1 on failure)
    lss layouts plot NAME|FILE [--out DIR] [--format png,svg]
    lss layouts design [--check]         write the seven layouts from their designs (lss_fmu.layout_design)
"""
from __future__ import annotations

import sys
from pathlib import Path

from lss_fmu.layouts import (TABLE2, LayoutError, builtin_layouts, check_layout, load_track, summary,
                             table2_mismatches)


def _table(out) -> int:
    head = (f"{'layout':<9} {'length m':>9} {'carts':>6} {'motors':>7} {'level ch.':>9} {'spirals':>7} "
            f"{'wheel':>5} {'coupl.':>6} {'closure m':>10} {'mrad':>8}  Table 2")
    print(head, file=out)
    print("-" * len(head), file=out)
    bad = 0
    for name in builtin_layouts():
        try:
            row = summary(load_track(name))
        except LayoutError as exc:
            print(f"{name:<9} error: {exc}", file=out)
            bad += 1
            continue
        miss = table2_mismatches(row)
        ref = "" if name not in TABLE2 else ("matches" if not miss else "; ".join(miss))
        bad += bool(miss)
        print(f"{name:<9} {row['length']:9.2f} {row['carts']:6d} {row['motors']:7d} {row['level_changes']:9d} "
              f"{row['spirals']:7d} {row['wheel']:>5} {row['coupling']:>6} {row['closure_m']:10.1e} "
              f"{row['closure_rad'] * 1e3:8.1e}  {ref}", file=out)
    return 1 if bad else 0


def _check(targets: list, out, err) -> int:
    rc = 0
    for target in targets:
        try:
            row = summary(check_layout(target))
        except LayoutError as exc:
            print(f"lss layouts check: {' '.join(str(exc).split())}", file=err)
            rc = 1
            continue
        print(f"{target}: closes to {row['closure_m']:.2e} m and {row['closure_rad'] * 1e3:.2e} mrad; "
              f"{row['length']:.3f} m, {row['carts']} carts, {row['motors']} motors, "
              f"{row['level_changes']} level changes, {row['spirals']} spirals, "
              f"wheel {row['wheel']}, coupling {row['coupling']}", file=out)
    return rc


def _plot(target: str, out_dir: str, formats: str, out, err) -> int:
    from .figures.layout import save_layout_plot
    fmts = [f.strip().lower() for f in formats.split(",") if f.strip()]
    unknown = [f for f in fmts if f not in ("png", "svg", "pdf")]
    if not fmts or unknown:
        print(f"lss layouts plot: unknown format {','.join(unknown) or formats!r} (png, svg, pdf)", file=err)
        return 2
    try:
        track = load_track(target)
    except LayoutError as exc:
        print(f"lss layouts plot: {' '.join(str(exc).split())}", file=err)
        return 1
    for p in save_layout_plot(track, Path(out_dir), fmts):
        print(p, file=out)
    return 0


def _design(check: bool, out, err) -> int:
    from lss_fmu.layout_design import DESIGNS, LAYOUT_DIR, generate
    stale = generate(check=check)
    if check:
        for n in stale:
            print(f"{n}.layout differs from its design", file=err)
        return 1 if stale else 0
    print(f"wrote {len(DESIGNS)} layouts to {LAYOUT_DIR} ({len(stale)} changed)", file=out)
    return 0


def register(sub, common) -> None:
    ap = sub.add_parser("layouts", parents=[common], help="list, check, draw and design track layouts",
                        description="Track layouts: Table 2, checks, drawings.")
    ap.set_defaults(run=run, cmd=None)
    lsub = ap.add_subparsers(dest="cmd")
    lsub.add_parser("table", help="Table 2 measured from the built-in layout files (the default)")
    chk = lsub.add_parser("check", help="check layout files: syntax, closure, motors")
    chk.add_argument("files", nargs="+", metavar="FILE", help="layout file or built-in name")
    plt = lsub.add_parser("plot", help="draw a layout (top view and elevation profile)")
    plt.add_argument("layout", metavar="NAME|FILE")
    plt.add_argument("--out", default=".", help="output directory (default: .)")
    plt.add_argument("--format", default="png,svg", help="comma-separated: png, svg, pdf (default png,svg)")
    des = lsub.add_parser("design", help="write the built-in layout files from their designs")
    des.add_argument("--check", action="store_true", help="only report files that differ from the designs")


def run(args, out=None, err=None) -> int:
    out = out or sys.stdout
    err = err or sys.stderr
    if args.cmd in (None, "table"):
        return _table(out)
    if args.cmd == "check":
        return _check(args.files, out, err)
    if args.cmd == "design":
        return _design(args.check, out, err)
    return _plot(args.layout, args.out, args.format, out, err)
