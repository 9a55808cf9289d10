#!/usr/bin/env python3
"""The paper's question with ground truth (issue 17, item 5): which contact
law fits the field set best, and what its identified CoRs mean.

The field set (`lss rig --set field --protocol start-stop`) is made with the
GZ law (exact restitution), as-built tracks, a mass spread and a guide gap,
none of which the candidate laws or the design track have. Each measurement
is identified with HC, HW, LW and LN (and GZ as the control: the true law on
the design track), the four CoRs free and the six layout-dependent variables
held at the values the rig drew (`problem.drive_known`), objective
"likelihood" (f is about 7 where only the noise is left). Every identified
CoR is then converted through its law to the restitution an impact really
has (`contact_laws.effective_restitution`) and compared with the true
restitution (GZ: the nominal value).

Two conditions: as a user would run it (the design track, the nominal cart
mass, no guide gap), and `--surveyed`, with the as-built track, the mass
factor and the guide gap the rig used given to the FMU, so that the law is
the only thing that differs from the truth. Which law fits best: the count of
measurements where each law has the lowest f, and Friedman's test over the
measurements (scipy.stats) for "the laws fit alike".

    .venv/bin/python benchmarks/bench_field_laws.py --measurements 1-22 \\
        --json benchmarks/results/field_laws.json
    .venv/bin/python benchmarks/bench_field_laws.py --report --figure docs/figures/field_laws.png

One result file per measurement and law under --work, written atomically: a
stopped run resumes where it was.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.contact_laws import effective_restitution  # noqa: E402
from lss_fmu.design import CORS, SYMBOL  # noqa: E402
from lss_fmu.rig import generate_set, load_truth, parse_numbers, true_design_values  # noqa: E402

LAWS = ("HC", "HW", "LW", "LN", "GZ")
# the cost of one identification grows with the chain: cheap layouts first, so a
# stopped run has the widest coverage
LAYOUT_ORDER = ("layout7", "layout6", "layout2", "layout1", "layout4", "layout5", "layout3")


def surveyed(meas_dir: Path, truth: dict) -> dict:
    """FMU parameters of what a survey of the sorter would give: its as-built
    track, the carts' mass factor and the guide gap the rig drew."""
    dev = truth.get("field_deviations") or {}
    fixed = {k: float(dev[k]) for k in ("cart.mass_factor", "track.guide_gap") if k in dev}
    if dev.get("as_built_file"):
        fixed["layout.name"] = str(Path(meas_dir).parent / dev["as_built_file"])
    return fixed


def identify_one(meas_dir: str, law: str, settings: dict) -> dict:
    """One measurement with one law, the drive known; the result as a dict."""
    from identification.pipeline.identify import identify
    from identification.objective.problem import drive_known, from_measurement
    from lss_fmu.measurement import load_measurement
    m = load_measurement(meas_dir)
    truth = load_truth(m)
    values = true_design_values(truth)
    fixed = surveyed(Path(meas_dir), truth) if settings["surveyed"] else {}
    p = drive_known(from_measurement(m, law, window=settings["window"], tare=True, objective="likelihood",
                                     fixed=fixed), values)
    c0 = time.process_time()
    try:
        res = identify(p, max_evals=settings["max_evals"], seed=settings["seed"], progress=False,
                       refine_evals=settings["refine_evals"], uncertainty=True)
        out = res.to_dict()
        out["f_at_true_cors"] = float(p(np.array([values[n] for n in p.free])))
    finally:
        p.sim.close()
    out.update({"cpu_s": time.process_time() - c0, "law": law, "number": truth["number"],
                "layout": m.layout, "measurement_dir": str(meas_dir), "true_cor": truth["cor"],
                "surveyed": fixed})
    return out


def row_of(r: dict) -> dict:
    """The identified CoRs of one result as true restitutions (through the law)."""
    law, row = r["law"], {"law": r["law"], "number": r["number"], "layout": r["layout"], "f": r["f"],
                          "f_at_true_cors": r.get("f_at_true_cors"), "cpu_s": r["cpu_s"]}
    for k in CORS:
        s = SYMBOL[k]
        e = r["values"][s]
        iv = (r.get("interval") or {}).get(s) or {}
        eff = effective_restitution(law, e)
        true = r["true_cor"][s]
        ident = iv.get("identifiable")
        lo, hi = iv.get("lower"), iv.get("upper")
        row[s] = {"nominal": e, "effective": eff, "true": true, "error": eff - true,
                  "identifiable": ident, "at_bound": bool(min(e - 0.2, 0.9 - e) < 1e-3),
                  "effective_interval": ([effective_restitution(law, min(max(lo, 1e-6), 1.0)),
                                          effective_restitution(law, min(max(hi, 1e-6), 1.0))]
                                         if ident and lo is not None and hi is not None else None)}
    return row


def load_rows(out: Path) -> list:
    return [row_of(json.loads(p.read_text())) for p in sorted(out.glob("m*_*.json"))]


def report(rows: list) -> dict:
    from scipy import stats
    laws = [law for law in LAWS if any(q["law"] == law for q in rows)]
    by = {(q["number"], q["law"]): q for q in rows}
    complete = sorted({q["number"] for q in rows if all((q["number"], law) in by for law in laws)})
    out = {"laws": laws, "measurements": complete, "per_law": {}}
    candidates = [law for law in laws if law != "GZ"]
    best = {law: 0 for law in candidates}
    for n in complete:
        best[min(candidates, key=lambda law: by[(n, law)]["f"])] += 1
    for law in laws:
        qs = [by[(n, law)] for n in complete]
        entry = {"best_of_candidates": best.get(law), "f_median": float(np.median([q["f"] for q in qs])),
                 "cpu_s_median": float(np.median([q["cpu_s"] for q in qs]))}
        for s in ("e_JA", "e_SW", "e_RW", "e_JR"):
            errs = np.array([q[s]["error"] for q in qs])
            entry[s] = {"median_abs_error": float(np.median(np.abs(errs))),
                        "within_0.03": int(np.sum(np.abs(errs) <= 0.03)),
                        "at_bound": int(sum(q[s]["at_bound"] for q in qs)),
                        "not_identifiable": int(sum(q[s]["identifiable"] is False for q in qs))}
        out["per_law"][law] = entry
    if len(complete) >= 3 and len(candidates) >= 3:
        fs = [[np.log(by[(n, law)]["f"]) for n in complete] for law in candidates]
        res = stats.friedmanchisquare(*fs)
        out["friedman"] = {"statistic": float(res.statistic), "p_value": float(res.pvalue),
                           "laws": candidates, "n": len(complete)}
    return out


def table(rows: list) -> str:
    laws = [law for law in LAWS if any(q["law"] == law for q in rows)]
    by = {(q["number"], q["law"]): q for q in rows}
    numbers = sorted({q["number"] for q in rows})
    lines = ["| meas | layout | " + " | ".join(f"{law} f" for law in laws) + " | "
             + " | ".join(f"{law} eff. e_JA/e_SW/e_RW err" for law in laws) + " |",
             "|" + "---|" * (2 + 2 * len(laws))]
    for n in numbers:
        q0 = next(q for q in rows if q["number"] == n)
        fs = [f"{by[(n, law)]['f']:.1f}" if (n, law) in by else "" for law in laws]
        errs = ["/".join(f"{by[(n, law)][s]['error']:+.2f}" for s in ("e_JA", "e_SW", "e_RW"))
                if (n, law) in by else "" for law in laws]
        lines.append(f"| {n} | {q0['layout'][6:]} | " + " | ".join(fs) + " | " + " | ".join(errs) + " |")
    return "\n".join(lines)


def summary_table(summary: dict) -> str:
    """One line per law: how often it fits best, its median f, and per CoR the
    median |effective - true| with the count within 0.03 and the count on a bound."""
    n = len(summary["measurements"])
    lines = ["| law | best of HC/HW/LW/LN | median f | e_JA: median err, within 0.03, on a bound | e_SW | e_RW | "
             "e_JR |", "|" + "---|" * 7]
    for law, e in summary["per_law"].items():
        cells = [f"{e[s]['median_abs_error']:.3f}, {e[s]['within_0.03']}/{n}, {e[s]['at_bound']}"
                 for s in ("e_JA", "e_SW", "e_RW", "e_JR")]
        best = "control" if e["best_of_candidates"] is None else f"{e['best_of_candidates']}/{n}"
        lines.append(f"| {law} | {best} | {e['f_median']:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def figure(rows: list, path: Path, surveyed: bool) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    laws = [law for law in LAWS if any(q["law"] == law for q in rows)]
    fig, axes = plt.subplots(1, 4, figsize=(14, 3.8), sharey=True)
    for ax, s in zip(axes, ("e_JA", "e_SW", "e_RW", "e_JR")):
        for i, law in enumerate(laws):
            qs = [q for q in rows if q["law"] == law]
            tr = [q[s]["true"] for q in qs]
            ef = [q[s]["effective"] for q in qs]
            nom = [q[s]["nominal"] for q in qs]
            ax.scatter(tr, ef, s=18, color=f"C{i}", label=f"{law}: effective")
            ax.scatter(tr, nom, s=10, color=f"C{i}", marker="x", alpha=0.5)
        ax.plot([0.2, 0.9], [0.2, 0.9], "k:", lw=1)
        for i, law in enumerate(laws):   # the least restitution a law reaches inside the CoR bounds
            if law != "GZ":
                ax.axhline(effective_restitution(law, 0.2), color=f"C{i}", lw=0.8, ls="--", alpha=0.6)
        ax.set_title(s)
        ax.set_xlabel("true restitution")
    axes[0].set_ylabel("identified (o: effective, x: nominal)")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"Field set (GZ truth), start-stop, drive known, {'sorter surveyed' if surveyed else 'design track'}: "
                 "identified CoR per law "
                 "(dashed: the least restitution each law reaches at e = 0.2)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="build/bench_field_laws")
    ap.add_argument("--measurements", default="1-22")
    ap.add_argument("--laws", default=",".join(LAWS))
    ap.add_argument("--max-evals", type=int, default=120)
    ap.add_argument("--refine-evals", type=int, default=40)
    ap.add_argument("--window", type=float, default=2.5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--json", default=None)
    ap.add_argument("--surveyed", action="store_true",
                    help="give the FMU the as-built track, mass factor and guide gap (the law the only difference)")
    ap.add_argument("--report", action="store_true", help="only tabulate what is under --work")
    ap.add_argument("--figure", default=None)
    args = ap.parse_args(argv)
    work = Path(args.work)
    data, out = work / "data", work / ("results_surveyed" if args.surveyed else "results")
    out.mkdir(parents=True, exist_ok=True)
    laws = [law.strip().upper() for law in args.laws.split(",") if law.strip()]
    if not set(laws) <= set(LAWS):
        ap.error(f"--laws: unknown {sorted(set(laws) - set(LAWS))}; known: {', '.join(LAWS)}")
    if not args.report:
        numbers = parse_numbers(args.measurements)
        from bench_recovery import set_fmu
        generate_set("field", data, numbers, workers=1, protocol="start-stop", progress=False,
                     log=lambda msg: print(msg, file=sys.stderr), fmu=set_fmu(data))
        layout = {n: load_truth(data / f"m{n:02d}")["layout"] for n in numbers}
        jobs = sorted(((n, law) for n in numbers for law in laws if not (out / f"m{n:02d}_{law}.json").exists()),
                      key=lambda j: (LAYOUT_ORDER.index(layout[j[0]]), j[0], laws.index(j[1])))
        settings = {"window": args.window, "max_evals": args.max_evals, "refine_evals": args.refine_evals,
                    "seed": args.seed, "surveyed": args.surveyed}
        print(f"{len(jobs)} identifications to run", file=sys.stderr)
        with ProcessPoolExecutor(max_workers=args.workers) as ex:
            futs = {ex.submit(identify_one, str(data / f"m{n:02d}"), law, settings): (n, law) for n, law in jobs}
            for i, fut in enumerate(as_completed(futs), 1):
                n, law = futs[fut]
                r = fut.result()
                write_json_atomic(out / f"m{n:02d}_{law}.json", r)
                print(f"[{i}/{len(jobs)}] m{n:02d} {law}: f {r['f']:.2f} (at true CoRs {r['f_at_true_cors']:.2f}), "
                      f"{r['cpu_s']:.0f} CPU-s", file=sys.stderr, flush=True)
    rows = load_rows(out)
    summary = report(rows)
    print(table(rows))
    print()
    print(summary_table(summary))
    if "friedman" in summary:
        fr = summary["friedman"]
        print(f"\nFriedman (log f, {', '.join(fr['laws'])} over {fr['n']} measurements): "
              f"chi^2 {fr['statistic']:.1f}, p = {fr['p_value']:.2g}")
    if args.json:
        write_json_atomic(args.json, {"command": " ".join(sys.argv), "settings": vars(args), "rows": rows,
                                      "summary": summary})
    if args.figure:
        figure(rows, Path(args.figure), args.surveyed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
