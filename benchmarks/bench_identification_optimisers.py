#!/usr/bin/env python3
"""Complex-RF against two reference optimisers on the real identification problem.

The problem is the release transient of tests/test_identification.py: layout 7,
contact model LW, the four CoRs free in 0.2..0.9 (the other design variables
at the truth), the first 0.6 s after the trigger, the measurement being the
model at the truth (Table 3, row 1) plus the sensor model's noise.  It is
built here the same way as the test's `release_problem` fixture
(:func:`release_problem`).

Methods, each from the same seeds with the same evaluation budget:

* ``complex-rf``   serial Complex-RF through ``identify(workers=1)``
* ``complex-rfp``  Complex-RFP (speculative) through ``identify(workers=2)``: two
                   worker processes with an FMU each; the budget counts the
                   evaluations the method uses, the discarded speculative ones
                   are reported apart
* ``de``           ``scipy.optimize.differential_evolution`` and
* ``cma-es``       ``cma``, both with the settings of benchmarks/bench_optimizers.py

Recorded per run: best f, the distance of each CoR from the truth, evaluations,
wall and CPU time; the JSON goes to benchmarks/results/identification_optimisers.json
and a section "On the identification problem" into docs/optimizer_benchmark.md.

One evaluation is timed first; if the estimated CPU time of the whole run is
above ``--cpu-limit`` the seeds, then the budget, are reduced (and the output says so).

    .venv/bin/python benchmarks/bench_identification_optimisers.py               # budget 300, seeds 0-2
    .venv/bin/python benchmarks/bench_identification_optimisers.py --from-json   # rewrite the doc section only

The FMU is build/LSSChain.fmu (built if missing), copied once at the start so
that a rebuild during the run does not change the model under the benchmark.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "benchmarks"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from bench_common import machine  # noqa: E402  (sets one BLAS thread first)

import numpy as np  # noqa: E402

from identification.objective.problem import DESIGN, IdentificationProblem  # noqa: E402

METHODS = ("complex-rf", "complex-rf-restart", "complex-rfp", "de", "cma-es")
RESTARTS = 10   # complex-rf-restart: identify(restarts=RESTARTS)
RESULTS = ROOT / "benchmarks" / "results" / "identification_optimisers.json"
DOC = ROOT / "docs" / "optimizer_benchmark.md"
SECTION = "## On the identification problem"
START, END = "<!-- identification-benchmark:start -->", "<!-- identification-benchmark:end -->"

# the release-transient problem of tests/test_identification.py
CORS = DESIGN[:4]
TRUTH = {"contact.e_JA": 0.46, "contact.e_JR": 0.558, "contact.e_SW": 0.351, "contact.e_RW": 0.645,
         "drive.v_ref": 2.0, "chain.pretension": 0.03, "wheel.mu_roll": 0.015, "trigger.s_M": 0.3,
         "drive.Kp": 500.0, "drive.Ki": 200.0}
FIXED = {"track.guide_gap": -0.0003}
SHORT_COR = {"contact.e_JA": "e_JA", "contact.e_JR": "e_JR", "contact.e_SW": "e_SW", "contact.e_RW": "e_RW"}
IDENTIFIABLE = ("contact.e_JA", "contact.e_SW", "contact.e_RW")  # e_JR is below the noise (docs/identification.md)
# convergence targets, as multiples of the noise floor f(truth): evaluations until the best f is below
TARGETS = (20.0, 5.0, 2.0)


# --------------------------------------------------------------------------
# the problem, on a pinned copy of the FMU
# --------------------------------------------------------------------------

def pin_fmu(workdir: Path) -> dict:
    """Copy build/LSSChain.fmu (built if missing) into `workdir`; the problem
    then runs on the copy (release_problem(fmu["path"]))."""
    from lss_fmu.runner import fmu_path
    src = fmu_path()
    dst = Path(workdir) / "LSSChain.fmu"
    for attempt in range(5):
        try:
            shutil.copyfile(src, dst)
            from fmpy import read_model_description
            guid = read_model_description(str(dst)).guid
            break
        except Exception:  # noqa: BLE001 - replaced while copying: try again
            if attempt == 4:
                raise
            time.sleep(1.0 + attempt)
    return {"fmu": str(src), "guid": guid, "bytes": dst.stat().st_size, "path": str(dst)}


def release_problem(fmu: str | None = None) -> IdentificationProblem:
    """The test's release transient (identification.loop.synthetic.release_problem),
    simulated by the FMU at `fmu` (one instance per process)."""
    from identification.loop.synthetic import release_problem as make
    from lss_fmu.runner import LazySimulator
    return make(sim=LazySimulator(fmu))


# --------------------------------------------------------------------------
# runs
# --------------------------------------------------------------------------


def _cpu() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _best_at(f_trace: np.ndarray, marks: list[int]) -> dict:
    f = np.where(np.isfinite(f_trace), f_trace, np.inf)
    best = np.minimum.accumulate(f) if f.size else f
    return {str(m): (float(best[min(m, f.size) - 1]) if f.size else None) for m in marks}


def evals_to(f_trace: np.ndarray, level: float) -> int | None:
    """1-based count of used evaluations until the best f is at or below `level`."""
    hit = np.flatnonzero(np.where(np.isfinite(f_trace), f_trace, np.inf) <= level)
    return int(hit[0]) + 1 if hit.size else None


def run_one(method: str, problem: IdentificationProblem, budget: int, seed: int,
            f_truth: float | None = None) -> dict:
    truth = np.array([TRUTH[k] for k in CORS])
    marks = sorted({100, 300, 500, budget})
    w0, c0 = time.perf_counter(), _cpu()
    if method in ("complex-rf", "complex-rf-restart", "complex-rfp"):
        from identification.pipeline.identify import identify
        workers = 2 if method == "complex-rfp" else 1
        res = identify(problem, max_evals=budget, seed=seed, progress=False, workers=workers,
                       restarts=RESTARTS if method == "complex-rf-restart" else 0)
        x, f = np.asarray(res.x), float(res.f)
        trace = np.asarray(res.history_f)
        info = {"nfev": int(res.nfev), "nfev_total": int(res.nfev_total), "simulated": int(res.evaluated),
                "rounds": int(res.nrounds), "message": res.message, "workers": workers,
                "n_bad": int(res.optimizer.n_bad)}
    else:
        from bench_optimizers import run_method
        r = run_method(method, problem, problem.bounds_array, budget, seed)
        x, f = np.asarray(r.x_best), float(r.f_best)
        trace = np.asarray(r.f_trace)
        info = {"nfev": int(r.nfev), "nfev_total": int(r.nfev), "simulated": int(r.nfev),
                "message": r.info.get("message"), "workers": 1}
    wall, cpu = time.perf_counter() - w0, _cpu() - c0
    err = {SHORT_COR[k]: float(v) for k, v in zip(CORS, x - truth)}
    return {"method": method, "seed": int(seed), "budget": int(budget), "f": f,
            "x": {SHORT_COR[k]: float(v) for k, v in zip(CORS, x)}, "error": err,
            "max_abs_error_identifiable": float(max(abs(err[SHORT_COR[k]]) for k in IDENTIFIABLE)),
            "best_f_after": _best_at(trace, marks), "wall_s": wall, "cpu_s": cpu,
            "evals_to": ({} if f_truth is None else
                         {f"{k:g}": evals_to(trace, k * f_truth) for k in TARGETS}), **info}


def time_one_evaluation(problem: IdentificationProblem, n: int = 3) -> float:
    xs = np.random.default_rng(123).uniform(0.2, 0.9, size=(n, len(CORS)))
    c0 = time.process_time()
    for x in xs:
        problem(x)
    return (time.process_time() - c0) / n


def size_run(t_eval: float, budget: int, seeds: int, cpu_limit: float) -> tuple[int, int, float, list[str]]:
    """(budget, seeds, estimated CPU s, notes): the seeds, then the budget, cut to
    fit the CPU limit. Complex-RFP is counted with 1.8x its budget (speculation)."""
    per_eval_runs = 1 + 1.8 + 1 + 1
    notes = []

    def est(b, s):
        return t_eval * b * s * per_eval_runs + 4 * s * len(METHODS) * t_eval  # + H0/H per run
    b, s = budget, seeds
    while est(b, s) > cpu_limit and s > 1:
        s -= 1
    while est(b, s) > cpu_limit and b > 60:
        b = int(b * 0.8)
    if s != seeds:
        notes.append(f"seeds cut from {seeds} to {s} to stay within {cpu_limit:.0f} s CPU")
    if b != budget:
        notes.append(f"budget cut from {budget} to {b} to stay within {cpu_limit:.0f} s CPU")
    return b, s, est(b, s), notes


# --------------------------------------------------------------------------
# summary and doc
# --------------------------------------------------------------------------


def summarize(runs: list[dict]) -> dict:
    out = {}
    for m in METHODS:
        rs = [r for r in runs if r["method"] == m]
        if not rs:
            continue
        out[m] = {
            "runs": len(rs),
            "f_median": float(np.median([r["f"] for r in rs])),
            "f_best": float(np.min([r["f"] for r in rs])),
            "f_worst": float(np.max([r["f"] for r in rs])),
            "within_0.03": int(sum(r["max_abs_error_identifiable"] <= 0.03 for r in rs)),
            "max_abs_error_median": float(np.median([r["max_abs_error_identifiable"] for r in rs])),
            "nfev_median": float(np.median([r["nfev"] for r in rs])),
            "nfev_total_median": float(np.median([r["nfev_total"] for r in rs])),
            "rounds_median": (float(np.median([r["rounds"] for r in rs])) if all("rounds" in r for r in rs)
                              else None),
            "wall_s_median": float(np.median([r["wall_s"] for r in rs])),
            "cpu_s_median": float(np.median([r["cpu_s"] for r in rs])),
            "evals_to": {k: _spread([r.get("evals_to", {}).get(k) for r in rs]) for k in
                         (rs[0].get("evals_to") or {})},
        }
    return out


def _spread(values: list) -> dict:
    """Reached count, median and interquartile range of the runs that reached."""
    hit = [v for v in values if v is not None]
    if not hit:
        return {"reached": 0, "runs": len(values), "median": None, "q1": None, "q3": None}
    q1, med, q3 = np.percentile(hit, [25, 50, 75])
    return {"reached": len(hit), "runs": len(values), "median": float(med), "q1": float(q1), "q3": float(q3)}


def _stop(message) -> str:
    m = str(message)
    return {"Maximum number of iterations has been exceeded.": "max iterations"}.get(m, m)


def _e(v: float) -> str:
    return f"{v:+.3f}"


def doc_section(data: dict) -> str:
    s = data["settings"]
    runs = data["runs"]
    summ = data["summary"]
    seeds = sorted({r["seed"] for r in runs})
    lines = [
        START, SECTION, "",
        f"Written by `benchmarks/bench_identification_optimisers.py` ({s['date']}, "
        f"{s['wall_s']:.0f} s wall time, {s['cpu_s']:.0f} s CPU); the figures are in "
        "`benchmarks/results/identification_optimisers.json`. Command:", "",
        f"    {s['command']}", "",
        f"Machine: {s['machine']}; numpy {s['versions']['numpy']}, scipy {s['versions']['scipy']}, "
        f"cma {s['versions']['cma']}. Shared with other work: load average {s['load_before']} before, "
        f"{s['load_after']} after the run, so wall times are indicative.", "",
        "The problem is the release transient of `tests/test_identification.py` (layout 7, LW, the four "
        "CoRs free in 0.2..0.9, the other design variables at the truth, the first 0.6 s after the "
        "trigger, the measurement being the model at the truth plus the sensor model's noise). "
        f"One evaluation (one simulation) costs {1000 * s['t_eval_s']:.0f} ms CPU. "
        f"f at the start point (all CoRs 0.55) is {s['f_x0']:.4g}; f at the truth, the noise floor, "
        f"is {s['f_truth']:.3g}.", "",
        f"Budget {s['budget']} evaluations per run, seeds {', '.join(map(str, seeds))}. "
        "Complex-RF through `identify(workers=1)` (start point in the initial complex, defaults "
        "f_tol 1e-6, x_tol 1e-4), as published; complex-rf-restart the same with "
        f"`identify(restarts={RESTARTS})`: a converged complex starts again in a box of +-15 % of the "
        "bounds around the best point until the budget is used; Complex-RFP through `identify(workers=2)`: two worker processes with "
        "an FMU each, the speculative strategy, whose budget counts the evaluations the method uses "
        "(the discarded speculative ones are in *evals total*); differential evolution (scipy, popsize "
        f"15, i.e. {15 * len(CORS)} points and {max(1, s['budget'] // (15 * len(CORS)) - 1) + 1} generations "
        "in this budget, `updating=\"deferred\"`, no polish) and "
        "CMA-ES (`cma`, CoRs scaled to [0, 1], sigma0 0.3, random start) with the settings of the test "
        "functions above, in one process.",
    ]
    if s.get("notes"):
        lines += ["", "Sizing: " + "; ".join(s["notes"]) + "."]
    lines += [
        "", "Per method over the seeds: best f (median and range), runs whose e_JA, e_SW and e_RW are "
        "all within ±0.03 of the truth (the recovery test's criterion; e_JR is below the noise, "
        "docs/identification.md), the median of the largest of those three errors, evaluations used "
        "and total, the median wall-clock rounds (batches of simulations run at once; Complex-RF only) "
        "and the median wall and CPU time of one run (CPU including the worker processes).",
        "",
        "| method | best f, median [min-max] | within ±0.03 | max error e_JA/e_SW/e_RW, median | evals used / total | rounds | wall s | CPU s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for m, v in summ.items():
        lines.append(f"| {m} | {v['f_median']:.3g} [{v['f_best']:.3g}-{v['f_worst']:.3g}] | "
                     f"{v['within_0.03']}/{v['runs']} | {v['max_abs_error_median']:.3f} | "
                     f"{v['nfev_median']:.0f} / {v['nfev_total_median']:.0f} | "
                     f"{'-' if v.get('rounds_median') is None else format(v['rounds_median'], '.0f')} | "
                     f"{v['wall_s_median']:.0f} | "
                     f"{v['cpu_s_median']:.0f} |")
    targets = list(next(iter(summ.values()), {}).get("evals_to", {}))
    if targets:
        lines += [
            "", "**Evaluations to converge**: used evaluations until the best f first falls to a multiple "
            "of the noise floor f(truth); runs that reached it / all runs, then the median and "
            "interquartile range over the runs that reached it (none: '-').", "",
            "| method | " + " | ".join(f"f <= {k} x f(truth)" for k in targets) + " |",
            "|---|" + "---|" * len(targets),
        ]
        for m, v in summ.items():
            cells = []
            for k in targets:
                e = v["evals_to"][k]
                cells.append(f"{e['reached']}/{e['runs']}" + ("" if e["median"] is None else
                             f": {e['median']:.0f} [{e['q1']:.0f}-{e['q3']:.0f}]"))
            lines.append(f"| {m} | " + " | ".join(cells) + " |")
    marks = list(runs[0]["best_f_after"]) if runs else []
    lines += [
        "", "Every run: the distance of each CoR from the truth (identified minus true), the best f "
        f"after {', '.join(marks)} used evaluations, and how the run stopped.", "",
        "| method | seed | best f | e_JA | e_SW | e_RW | (e_JR) | best f after " + " / ".join(marks)
        + " | evals used / total | wall s | stop |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        e = r["error"]
        bf = " / ".join("-" if v is None else f"{v:.3g}" for v in r["best_f_after"].values())
        lines.append(f"| {r['method']} | {r['seed']} | {r['f']:.4g} | {_e(e['e_JA'])} | {_e(e['e_SW'])} | "
                     f"{_e(e['e_RW'])} | {_e(e['e_JR'])} | {bf} | {r['nfev']} / {r['nfev_total']} | "
                     f"{r['wall_s']:.0f} | {_stop(r['message'])} |")
    lines += ["", data.get("reading", "").strip(), END]
    return "\n".join(line for line in lines if line is not None) + "\n"


def write_doc(data: dict, path: Path = DOC) -> None:
    text = path.read_text() if path.exists() else "# Optimiser benchmark\n"
    section = doc_section(data)
    if START in text and END in text:
        a, b = text.index(START), text.index(END) + len(END)
        text = text[:a] + section.rstrip("\n") + text[b:]
    else:
        text = text.rstrip("\n") + "\n\n" + section
    path.write_text(text)


# --------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--budget", type=int, default=300)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--cpu-limit", type=float, default=900.0, help="CPU seconds the whole run may take")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--doc", default=str(DOC))
    ap.add_argument("--no-write", action="store_true", help="print only")
    ap.add_argument("--from-json", action="store_true", help="rewrite the doc section from --out, no runs")
    ap.add_argument("--reading", default=None, help="a file whose text goes below the tables")
    ap.add_argument("--merge", action="store_true",
                    help="keep the runs of the other methods already in --out (same budget and seeds)")
    args = ap.parse_args(argv)
    if args.from_json:
        data = json.loads(Path(args.out).read_text())
        data["summary"] = summarize(data["runs"])
        if args.reading:
            data["reading"] = Path(args.reading).read_text()
            Path(args.out).write_text(json.dumps(data, indent=1) + "\n")
        write_doc(data, Path(args.doc))
        print(f"rewrote the section in {args.doc}")
        return 0
    methods = [m for m in args.methods.split(",") if m]
    for m in methods:
        if m not in METHODS:
            raise SystemExit(f"unknown method {m!r}: {', '.join(METHODS)}")
    import cma
    import scipy

    load_before = " ".join(f"{v:.2f}" for v in os.getloadavg())
    w0, c0 = time.perf_counter(), _cpu()
    with tempfile.TemporaryDirectory(prefix="lss_bench_ident_") as tmp:
        fmu = pin_fmu(Path(tmp))
        problem = release_problem(fmu["path"])
        t_eval = time_one_evaluation(problem)
        f_truth = float(problem([TRUTH[k] for k in CORS]))
        f_x0 = float(problem(problem.x0_vector()))
        budget, n_seeds, est, notes = size_run(t_eval, args.budget, args.seeds, args.cpu_limit)
        print(f"one evaluation {1000 * t_eval:.0f} ms CPU; f(truth) {f_truth:.3g}, f(x0) {f_x0:.4g}; "
              f"budget {budget}, seeds {n_seeds}: about {est:.0f} s CPU" + ("; " + "; ".join(notes) if notes else ""),
              flush=True)
        runs = []
        for seed in range(n_seeds):
            for m in methods:
                r = run_one(m, problem, budget, seed, f_truth)
                runs.append(r)
                e = r["error"]
                print(f"{m:12s} seed {seed}: f {r['f']:.4g}  e_JA {e['e_JA']:+.3f} e_SW {e['e_SW']:+.3f} "
                      f"e_RW {e['e_RW']:+.3f} (e_JR {e['e_JR']:+.3f})  evals {r['nfev']}/{r['nfev_total']}  "
                      f"wall {r['wall_s']:.0f} s  cpu {r['cpu_s']:.0f} s  [{r['message']}]", flush=True)
    wall, cpu = time.perf_counter() - w0, _cpu() - c0
    cmd = ".venv/bin/python benchmarks/bench_identification_optimisers.py"
    if args.budget != 300 or args.seeds != 3 or args.methods != ",".join(METHODS):
        cmd += f" --budget {args.budget} --seeds {args.seeds} --methods {args.methods}"
    data = {
        "settings": {
            "date": _dt.date.today().isoformat(), "command": cmd, "machine": machine(),
            "python": platform.python_version(),
            "versions": {"numpy": np.__version__, "scipy": scipy.__version__, "cma": cma.__version__},
            "fmu": fmu, "problem": {"layout": "layout7", "model": "LW", "free": list(CORS),
                                    "bounds": [0.2, 0.9], "window_s": 0.6, "sample_rate": 300,
                                    "settle_s": 0.02, "fixed": FIXED, "truth": TRUTH, "noise_seed": 1},
            "t_eval_s": t_eval, "f_truth": f_truth, "f_x0": f_x0,
            "budget": budget, "seeds": n_seeds, "requested": {"budget": args.budget, "seeds": args.seeds},
            "cpu_estimate_s": est, "notes": notes, "wall_s": wall, "cpu_s": cpu,
            "load_before": load_before, "load_after": " ".join(f"{v:.2f}" for v in os.getloadavg()),
        },
        "runs": runs,
        "summary": summarize(runs),
    }
    if args.merge and Path(args.out).is_file():
        old = json.loads(Path(args.out).read_text())
        if (old["settings"]["budget"], old["settings"]["seeds"]) != (budget, n_seeds):
            raise SystemExit(f"--merge: {args.out} has budget {old['settings']['budget']} and "
                             f"{old['settings']['seeds']} seeds, this run {budget} and {n_seeds}")
        kept = [r for r in old["runs"] if r["method"] not in methods]
        data["runs"] = sorted(kept + runs, key=lambda r: (r["seed"], METHODS.index(r["method"])))
        data["summary"] = summarize(data["runs"])
        data["settings"]["merged"] = {"from": old["settings"]["date"], "methods_run_now": methods,
                                      "wall_s_now": wall, "cpu_s_now": cpu}
        for k in ("wall_s", "cpu_s"):
            data["settings"][k] = old["settings"][k] + data["settings"][k]
        data.setdefault("reading", old.get("reading", ""))
    if args.reading:
        data["reading"] = Path(args.reading).read_text()
    for m, v in data["summary"].items():
        print(f"{m:12s} f median {v['f_median']:.3g}  within 0.03: {v['within_0.03']}/{v['runs']}  "
              f"max err median {v['max_abs_error_median']:.3f}  wall {v['wall_s_median']:.0f} s", flush=True)
    print(f"total {wall:.0f} s wall, {cpu:.0f} s CPU")
    if not args.no_write:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(data, indent=1) + "\n")
        write_doc(data, Path(args.doc))
        print(f"wrote {args.out} and the section in {args.doc}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
