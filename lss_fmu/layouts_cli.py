"""`lss layouts ...`: Table 2 as measured, the closure checker, the drawings.

    lss layouts                          Table 2 measured from the built-in files
    lss layouts check FILE|NAME ...      closure in position and direction (exit 1 on failure)
    lss layouts plot NAME|FILE [--out DIR] [--format png,svg]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .layouts import (TABLE2, LayoutError, builtin_layouts, check_layout, load_track, summary, table2_mismatches)


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
    from .layout_plot import save_layout_plot
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


def layouts_main(argv: list, out=None, err=None) -> int:
    out = out or sys.stdout
    err = err or sys.stderr
    ap = argparse.ArgumentParser(prog="lss layouts", description="Track layouts: Table 2, checks, drawings.")
    sub = ap.add_subparsers(dest="cmd")
    sub.add_parser("table", help="Table 2 measured from the built-in layout files (the default)")
    chk = sub.add_parser("check", help="check layout files: syntax, closure, motors")
    chk.add_argument("files", nargs="+", metavar="FILE", help="layout file or built-in name")
    plt = sub.add_parser("plot", help="draw a layout (top view and elevation profile)")
    plt.add_argument("layout", metavar="NAME|FILE")
    plt.add_argument("--out", default=".", help="output directory (default: .)")
    plt.add_argument("--format", default="png,svg", help="comma-separated: png, svg, pdf (default png,svg)")
    try:
        args = ap.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    if args.cmd in (None, "table"):
        return _table(out)
    if args.cmd == "check":
        return _check(args.files, out, err)
    return _plot(args.layout, args.out, args.format, out, err)


if __name__ == "__main__":
    sys.exit(layouts_main(sys.argv[1:]))
