"""The recovery table of bench_recovery as a figure: each measurement's
identified minus true e_JA, e_SW and e_RW with its 95 % interval, against
the issue's +-0.03 (issue 17).

    .venv/bin/python benchmarks/plot_recovery.py benchmarks/results/recovery_start-stop_ten_free_k3_auto.json \
        --out docs/figures/recovery_k3_auto.png

A filled dot is within 0.03 with its interval claimed; a hollow one is
reported not identifiable (no interval); red marks a measurement where any
of the three misses (off by more, or not claimed). Every table in the file (one per protocol label) is
drawn, one row of panels each.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

CORS = ("e_JA", "e_SW", "e_RW")
TOL = 0.03
CLIP = 0.2   # errors beyond this are drawn at the edge (a failure's CoRs can be anywhere)


def hit(row: dict) -> bool:
    """All three claimed (not reported unidentifiable) and within TOL of the truth."""
    return all(row[c].get("identifiable") is not False and abs(row[c]["error"]) <= TOL for c in CORS)


def figure(tables: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(len(tables), len(CORS), figsize=(13, 3.6 * len(tables)), sharey=True, squeeze=False)
    for i, (label, rows) in enumerate(tables.items()):
        hits = sum(hit(r) for r in rows)
        for j, c in enumerate(CORS):
            ax = axes[i][j]
            ax.axhspan(-TOL, TOL, color="0.9", zorder=0)
            ax.axhline(0.0, color="0.5", lw=0.8)
            for r in rows:
                e, iv = r[c]["error"], r[c].get("interval") or {}
                y = max(-CLIP, min(CLIP, e))
                colour = "tab:blue" if hit(r) else "tab:red"
                claimed = r[c]["identifiable"] is not False and iv.get("sd") is not None
                if claimed:
                    ax.errorbar(r["number"], y, yerr=1.96 * iv["sd"], fmt="o", color=colour, ms=5, capsize=2)
                else:
                    ax.plot(r["number"], y, "o", mfc="none", color=colour, ms=6)
            ax.set_ylim(-CLIP * 1.05, CLIP * 1.05)
            ax.set_xlim(0.3, 22.7)
            ax.set_xticks(range(1, 23))
            ax.tick_params(axis="x", labelsize=7)
            ax.set_title(c, fontsize=9, loc="left")
            if j == 1:   # the table's label over its row of panels
                ax.annotate(f"{label}\n{hits} hits of {len(rows)} measured (all three within {TOL})",
                            xy=(0.5, 1.12), xycoords="axes fraction", ha="center", fontsize=10)
            if j == 0:
                ax.set_ylabel("identified - true")
            if i == len(tables) - 1:
                ax.set_xlabel("measurement")
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.14 / len(tables), top=1 - 0.2 / len(tables), wspace=0.08,
                        hspace=0.6)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", help="a bench_recovery --json file")
    ap.add_argument("--out", required=True, help="the figure (png or svg)")
    args = ap.parse_args(argv)
    src = Path(args.results)
    try:
        report = json.loads(src.read_text())
        if "protocols" in report:   # the tables of several pipelines, by label
            tables = {label: entry["rows"] for label, entry in report["protocols"].items() if entry.get("rows")}
        else:   # one campaign's table
            label = f"{report['protocol']}, {report['repeats']} records"
            tables = {label: report["rows"]} if report["rows"] else {}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"{src}: not a bench_recovery result file ({exc})", file=sys.stderr)
        return 2
    if not tables:
        print(f"{src}: no rows to draw", file=sys.stderr)
        return 2
    figure(tables, Path(args.out))
    print(f"{args.out}: {sum(len(r) for r in tables.values())} measurements")
    return 0


if __name__ == "__main__":
    sys.exit(main())
