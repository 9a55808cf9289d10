"""The refinement's budget, replayed (issue 17): what `--refine-evals N`
would have given on records already identified with `--grown --shrink`.

identify_grown ends with Levenberg-Marquardt on the whole record (and on each
shorter window `--shrink` tries), `refine_evals` simulations at most. Each of
those refinements stores its start point (JOURNAL.local.json, key "start"),
so the pipeline's last stage can be run again from exactly where it started,
with another budget, without the complex and the growing windows before it:
the same windows in the same order, the same roughness check. A window that
a larger budget would reach but the stored run never tried has no stored
start and ends the replay there (reported).

    .venv/bin/python benchmarks/bench_refine_budget.py --refine-evals 400 --measurements 6,7 \\
        --json benchmarks/results/refine_budget_400.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from types import SimpleNamespace

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from identification.pipeline.identify import local_stage  # noqa: E402
from identification.optim.journal import point_of  # noqa: E402
from identification.objective.problem import from_measurement  # noqa: E402
from identification.pipeline.windowing import LADDER, troubles, truncated  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.design import CORS  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import load_truth, parse_numbers, true_design_values  # noqa: E402


def stored_start(journals: Path, n: int, window) -> np.ndarray | None:
    name = f"m{n:02d}_LW.local.json" if window is None else f"m{n:02d}_LW.w{window:g}.local.json"
    p = journals / name
    if not p.exists():
        return None
    return point_of(json.loads(p.read_text())["key"]["start"])


def replay(data: Path, journals: Path, n: int, refine_evals: int, window: float) -> dict:
    m = load_measurement(data / f"m{n:02d}")
    truth = true_design_values(load_truth(m))
    problem = from_measurement(m, "LW", window=window, tare=True, objective="likelihood")
    c0 = time.process_time()
    full = float(problem.times[-1])
    steps = [None] + [s for s in LADDER if s < full - 1e-9]
    tried, out = [], None
    try:
        for s in steps:
            x0 = stored_start(journals, n, s)
            if x0 is None:
                tried.append({"window_s": s, "note": "no stored start: the stored run never tried it"})
                break
            q = problem if s is None else truncated(problem, s)
            f0 = float(q(x0))
            local = local_stage(q, x0, f0, refine_evals, True, None)
            x, f = (np.asarray(local["x"], float), float(local["f"])) if local.get("f", np.inf) < f0 else (x0, f0)
            ivs = local.get("intervals") or []
            trouble = troubles(SimpleNamespace(intervals=ivs))
            xt = np.array([truth[k] for k in q.free])
            out = {"window_s": float(q.times[-1]), "f": f, "f_start": f0, "f_truth": float(q(xt)),
                   "refined": local.get("refined"), "troubles": trouble,
                   "cors": {k: {"value": float(x[q.free.index(k)]), "truth": truth[k],
                                "sd": next((iv.sd for iv in ivs if iv.name == k), None),
                                "identifiable": next((iv.identifiable for iv in ivs if iv.name == k), None)}
                            for k in CORS}}
            tried.append({k: out[k] for k in ("window_s", "f", "troubles")})
            if not trouble:
                break
    finally:
        problem.sim.close()
    return {"number": n, "layout": m.layout, "refine_evals": refine_evals, "cpu_s": time.process_time() - c0,
            "tried": tried, **(out or {})}


def hit(r: dict, tol: float = 0.03) -> bool:
    c = r.get("cors") or {}
    return all(c.get(k) and c[k]["identifiable"] and abs(c[k]["value"] - c[k]["truth"]) <= tol
               for k in ("contact.e_JA", "contact.e_SW", "contact.e_RW"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="build/bench_recovery/start-stop")
    ap.add_argument("--runs", default="likelihood/grown/shrink/campaign",
                    help="the stored --grown --shrink campaign under --work")
    ap.add_argument("--measurements", default="1-22")
    ap.add_argument("--refine-evals", type=int, default=400)
    ap.add_argument("--window", type=float, default=2.5)
    ap.add_argument("--json", required=True)
    args = ap.parse_args(argv)
    work = Path(args.work)
    report = json.loads(Path(args.json).read_text()) if Path(args.json).exists() else {"rows": {}}
    report["command"] = " ".join(sys.argv)
    for n in parse_numbers(args.measurements):
        if str(n) in report["rows"]:
            continue
        r = replay(work / "data", work / args.runs / "journals", n, args.refine_evals, args.window)
        report["rows"][str(n)] = r
        write_json_atomic(args.json, report)   # one row at a time: an interrupted run resumes
        errs = " ".join(f"{k[-4:]} {v['value'] - v['truth']:+.3f}" + ("" if v["identifiable"] else " n.i.")
                        for k, v in (r.get("cors") or {}).items())
        print(f"m{n:02d} {r['layout']}: window {r.get('window_s')} f {r.get('f', float('nan')):.4g} "
              f"(truth {r.get('f_truth', float('nan')):.4g}) {errs} {'HIT' if hit(r) else 'miss'} "
              f"{(r.get('refined') or {}).get('nfev')} sims {r['cpu_s']:.0f} CPU-s", flush=True)
    rows = list(report["rows"].values())
    report["summary"] = {"records": len(rows), "all_three_within_0.03": sum(hit(r) for r in rows)}
    write_json_atomic(args.json, report)
    print(json.dumps(report["summary"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
