#!/usr/bin/env python3
"""False alarms and detection rates of the closed loop (issue 18, item 3).

Runs `identification.loop.close_loop` on records with a known truth and counts
what it concludes:

* clean records (no effect): synthetic release transients of layout 7 (noise
  seeds, transducer carts) and rig records (`lss rig`, recovery set) of
  several layouts and every protocol (start-up, speed step, stop, steady),
  through `from_measurement` as `lss close-loop` reads them. A *false
  confirmation* is any catalogue effect confirmed;
* one catalogue effect at a given amplitude (release transient of layout 7,
  the transducer cart, noise, channel, sign, phase, pitch, joint drawn per
  record): found when that effect is confirmed in round 1;
* one disturbance outside the catalogue (interference, clock drift,
  crosstalk, a pulse): correct when the verdict is "not in the catalogue".

Every case is written atomically to benchmarks/results/close_loop_rates/
<case>.json when done: an interrupted run resumes where it stopped. One
process, one core (the machine is shared).

Each case carries the stamp of the code it ran on (`code_stamp`: the loop's
sources, the FMU's C and the benchmark's case making), so the report can say
how many of its rows are of the current code; `run --stale` reruns the cases
stored under another stamp (a rerun of the whole set can span several
sessions as long as that code does not change).

    .venv/bin/python benchmarks/bench_close_loop_rates.py run [--part clean|detect|ooc|all] [--records 10]
        [--families mass,track_bump] [--amplitudes-index 0,1] [--ids ID,ID] [--limit N] [--stale]
    .venv/bin/python benchmarks/bench_close_loop_rates.py report [--figure docs/figures/close_loop_rates.png]
"""
from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import logging
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402
from scipy.stats import binomtest  # noqa: E402

from bench_common import hash_sources  # noqa: E402

from lss_fmu.atomic import write_json_atomic  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "close_loop_rates"
WORK = ROOT / "build" / "bench_close_loop_rates"
SUMMARY = ROOT / "benchmarks" / "results" / "close_loop_rates.json"

# the loop's budgets for the benchmark (small: records of 1 s)
BUDGET = dict(base_evals=80, max_evals=100, fit_evals=20, refine_evals=40, base_refine_evals=60, candidates=4, rounds=1,
              first_window=0.3)   # s, the base's first window (identification.pipeline.growing); 0: the whole record
CARTS = (0, 7, 13, 20, 26, 33, 39, 46)   # transducer carts of the release transient: in curves and on straights

# family -> (unit, amplitudes, what the amplitude is)
FAMILIES = {
    "sensor_gain": ("1", (0.02, 0.035, 0.05, 0.08, 0.15), "gain error g on one moving channel (|g| <= 0.03 is within "
                                                     "the specification)"),
    "sensor_offset": ("x tol", (1.1, 1.25, 1.5, 2.0, 3.0), "offset on one channel, in multiples of the zero "
                                                      "tolerance (3 sigma of the declared offset)"),
    "mass": ("1", (0.001, 0.002, 0.005, 0.01, 0.03, 0.25, 0.5), "transducer cart's mass factor - 1"),
    "track_bump": ("mm", (0.02, 0.05, 0.1, 0.25, 1.0, 2.0), "|height| of a bump at a random joint, passed by the "
                                                  "transducer cart at a random time of the record"),
    "joint_clearance": ("um", (0.1, 0.25, 0.5, 1.0, 4.0, 20.0), "gap in every joint"),
    "wheel_oor_1": ("um", (2.0, 5.0, 15.0, 40.0, 100.0, 300.0), "radial runout, 1 lobe (eccentric)"),
    "wheel_oor_2": ("um", (1.0, 2.5, 5.0, 10.0, 25.0, 80.0), "radial runout, 2 lobes"),
    "wheel_oor_3": ("um", (0.3, 1.0, 2.5, 5.0, 12.0, 40.0), "radial runout, 3 lobes"),
    "motor_ripple": ("N", (1.0, 2.5, 5.0, 10.0, 30.0, 100.0, 300.0), "thrust ripple amplitude, pitch 50-200 mm"),
}
OOC = ("interference", "clock_drift", "crosstalk", "channel_bump")

# clean rig records: (protocol, measurement number, window s); layouts 1, 2, 4, 5, 6, 7
RIG_CLEAN = [("start-up", 1, 1.0), ("start-up", 5, 1.0), ("start-up", 12, 1.0), ("start-up", 13, 1.0),
             ("start-up", 19, 1.0), ("start-up", 20, 1.0), ("speed-step", 20, 1.5), ("speed-step", 21, 1.5),
             ("stop", 20, 1.5), ("stop", 22, 1.5), ("steady", 20, 1.0), ("steady", 21, 1.0)]
SYN_CLEAN = 16


def _rng(*key) -> np.random.Generator:
    return np.random.default_rng([18, *[int(k) for k in key]])


# ------------------------------------------------------------------------------------------ the cases
def cases(part: str, records: int, families=None, amp_index=None, syn_clean: int = SYN_CLEAN) -> list:
    out = []
    if part in ("clean", "all"):
        out += [{"id": f"clean_syn_{r:02d}", "kind": "clean", "source": "synthetic", "record": r}
                for r in range(syn_clean)]
        out += [{"id": f"clean_rig_{proto}_m{n:02d}", "kind": "clean", "source": "rig", "protocol": proto,
                 "number": n, "window": wdw} for proto, n, wdw in RIG_CLEAN]
    if part in ("detect", "all"):
        for fam, (_, amps, _) in FAMILIES.items():
            if families and fam not in families:
                continue
            for ia, a in enumerate(amps):
                if amp_index is not None and ia not in amp_index:
                    continue
                out += [{"id": f"{fam}_a{ia}_r{r:02d}", "kind": "effect", "family": fam, "amplitude": a,
                         "amp_index": ia, "record": r} for r in range(records)]
    if part in ("ooc", "all"):
        out += [{"id": f"ooc_{name}_r{r:02d}", "kind": "ooc", "artefact": name, "record": r}
                for name in OOC for r in range(5)]
    return out


def _moving_channels(problem, x) -> list:
    sim = problem.simulate(x)
    return [j for j in range(sim.shape[1]) if np.std(sim[:, j]) > 20.0]


def synthetic_problem(case: dict):
    """(problem, truth dict) of a synthetic case."""
    from identification.loop.synthetic import (LAYOUT, TRUTH, cart_trigger, make_problem, transducer_before)
    from lss_fmu.layouts import load_track
    from lss_fmu.runner import LazySimulator
    from lss_fmu.sensor import OFFSET_STD
    from lss_fmu.variables import FORCE_CHANNELS
    sim = LazySimulator()
    r = int(case["record"])
    kind = case["kind"]
    key = (list(FAMILIES).index(case["family"]) + 1, case["amp_index"]) if kind == "effect" else \
        (100 + OOC.index(case["artefact"]), 0) if kind == "ooc" else (0, 0)
    rng = _rng(*key, r)
    noise_seed = int(rng.integers(1, 2 ** 31 - 1))
    cart = CARTS[r % len(CARTS)]
    s_m = None
    params, artefacts, artefact, truth = {}, None, None, {}
    x_truth = np.array([TRUTH[k] for k in ("contact.e_JA", "contact.e_JR", "contact.e_SW", "contact.e_RW")])
    if kind == "effect":
        fam, a = case["family"], float(case["amplitude"])
        sign = 1.0 if rng.random() < 0.5 else -1.0
        if fam == "sensor_gain":
            p0, _ = make_problem({}, noise_seed, transducer=cart, s_m=cart_trigger(cart, sim()), sim=sim)
            moving = _moving_channels(p0, x_truth)
            j = int(moving[int(rng.integers(len(moving)))])
            params = {f"effects.sensor.gain.{FORCE_CHANNELS[j].replace('transducer.', '')}": sign * a}
        elif fam == "sensor_offset":
            j = int(rng.integers(len(FORCE_CHANNELS)))
            tol = 3.0 * OFFSET_STD[FORCE_CHANNELS[j]]
            params = {f"effects.sensor.offset.{FORCE_CHANNELS[j].replace('transducer.', '')}": sign * a * tol}
        elif fam == "mass":
            params = {"effects.mass.transducer_factor": 1.0 + a}
        elif fam == "track_bump":
            tr = load_track(LAYOUT)
            s_b = float(tr.s0[int(rng.integers(len(tr.s0)))]) % float(tr.length)
            params = {"effects.track_bump.height": sign * a * 1e-3, "effects.track_bump.s": s_b,
                      "effects.track_bump.length": float(rng.uniform(0.1, 0.3))}
            cart, s_m = transducer_before(s_b, lead=float(rng.uniform(0.3, 1.5)), sim=sim())
        elif fam == "joint_clearance":
            params = {"effects.joint_clearance.gap": a * 1e-6}
        elif fam.startswith("wheel_oor"):
            params = {"effects.wheel_oor.amplitude": a * 1e-6, "effects.wheel_oor.order": int(fam[-1]),
                      "effects.wheel_oor.phase_left": float(rng.uniform(0, 2 * math.pi)),
                      "effects.wheel_oor.phase_right": float(rng.uniform(0, 2 * math.pi))}
        elif fam == "motor_ripple":
            params = {"effects.motor_ripple.amplitude": a, "effects.motor_ripple.pitch": float(rng.uniform(0.05, 0.2)),
                      "effects.motor_ripple.phase": float(rng.uniform(0, 2 * math.pi))}
        truth = {"params": params}
    elif kind == "ooc":
        name = case["artefact"]
        if name == "channel_bump":
            artefact = {"channel": FORCE_CHANNELS[int(rng.integers(len(FORCE_CHANNELS)))],
                        "t": float(rng.uniform(0.2, 0.8)), "width": float(rng.uniform(0.08, 0.2)),
                        "amplitude": float((1 if rng.random() < 0.5 else -1) * rng.uniform(30.0, 80.0))}
            truth = {"artefact": artefact}
        else:
            from lss_fmu import rig_effects
            artefacts = rig_effects.draw_artefacts([name], noise_seed, float(load_track(LAYOUT).length))
            truth = {"artefacts": artefacts}
    if s_m is None:
        s_m = cart_trigger(cart, sim())
    problem, _ = make_problem(params, noise_seed, transducer=cart, s_m=s_m, sim=sim, artefact=artefact,
                              artefacts=artefacts)
    truth.update({"transducer": cart, "noise_seed": noise_seed})
    return problem, truth, {}


def rig_problem(case: dict):
    """(problem, truth, close_loop keywords) of a rig record: made once into WORK (2 s logged), read back
    with its window as `lss close-loop` does."""
    from identification.objective.problem import from_measurement
    from lss_fmu.measurement import load_measurement
    from lss_fmu.rig import folder_name, generate_set, load_truth
    data = WORK / f"rig_{case['protocol']}_m{case['number']:02d}"   # one folder each: a set folder holds one kind of run
    folder = data / folder_name(case["number"])
    if not (folder / "meta.json").is_file():
        generate_set("recovery", data, [case["number"]], workers=1, lap_seconds=2.0, progress=False,
                     protocol=case["protocol"], log=lambda *a: None)
    meas = load_measurement(folder)
    problem = from_measurement(meas, "LW", window=case["window"], tare=True)
    sensor = meas.meta.get("sensor") or {}
    truth = load_truth(folder)
    return problem, {"layout": meas.layout, "protocol": case["protocol"],
                     "truth_design": truth.get("design_variables") or truth.get("truth")}, \
        {"sensor_offset_std": sensor.get("force_offset_std_N"), "noise_std": sensor.get("force_noise_std_N")}


def run_case(case: dict, budget: dict = BUDGET) -> dict:
    from identification.loop.close_loop import close_loop
    from identification.loop.settings import LoopSettings
    t0, c0 = time.time(), time.process_time()
    if case.get("source") == "rig":
        problem, truth, kw = rig_problem(case)
    else:
        problem, truth, kw = synthetic_problem(case)
    settings = {k: v for k, v in budget.items() if k != "rounds"}   # the rest are LoopSettings' fields
    res = close_loop(problem, seed=0, rounds=budget.get("rounds", 1), settings=LoopSettings(**settings), **kw)
    rounds = []
    for r in res.rounds:
        ev = r.evidence
        rounds.append({"outcome": r.outcome, "verdict": r.verdict, "effect": r.effect, "confirmed": r.confirmed,
                       "f_base": r.f_base, "S_base": r.S_base, "restarts": len(r.base_restarts),
                       "excess_max": float(np.max(r.excess.ratio)) if r.excess is not None else None,
                       "noise": r.noise.source if r.noise else None,
                       "evidence": None if ev is None else {
                           "effect": ev.effect, "T": ev.lr.T, "dof": ev.lr.dof, "p": ev.lr.p, "p_adj": ev.lr.p_adj,
                           "dbic": ev.lr.dbic, "method": ev.lr.method, "holdout_gain": ev.holdout.gain,
                           "amplitude": ev.amplitude, "why_not": ev.why_not},
                       "tests": [(t.effect, t.lr.p_adj, t.lr.dbic, t.holdout.gain if t.holdout else None, t.supported,
                                  t.S / problem.samples.size, t.why_not) for t in r.tests],
                       # the fit with the base (candidates.examine_candidate), S per sample from each start
                       "joint_fits": {t.effect: [{"first_window": j.get("first_window", "effect held"),
                                                  "S_per_sample": j["S"] / problem.samples.size}
                                                 for j in t.refined.get("joint_starts", [])]
                                      for t in r.tests if t.refined.get("joint_starts")},
                       "S_base_per_sample": r.S_base / problem.samples.size,
                       "departures": [(d.family, d.label, d.test.p_adj, d.test.dbic) for d in r.departures],
                       "ranking": [(h.effect, h.share) for h in r.attribution.ranking[:4]],
                       "dropped": r.dropped})
    return {**case, "truth": truth, "found": res.found, "outcome": res.outcome, "verdict": res.verdict,
            "rounds": rounds, "layout": problem.layout, "protocol": problem.protocol.name,
            "samples": len(problem.times), "free": list(problem.free), "base_grown": res.grown,
            "wall_s": time.time() - t0, "cpu_s": time.process_time() - c0, "budget": budget}


def code_stamp() -> str:
    """A short hash of what decides a case's outcome: the loop's and the model's sources (identification,
    lss_fmu, fmu_src) and this file's case making and budgets; not the report, not the tests."""
    h = hash_sources(hashlib.sha256())
    for fn in (_rng, cases, _moving_channels, synthetic_problem, rig_problem, run_case):
        h.update(inspect.getsource(fn).encode())
    h.update(repr((BUDGET, CARTS, FAMILIES, OOC, RIG_CLEAN, SYN_CLEAN)).encode())
    return h.hexdigest()[:12]


def _commit() -> str:
    import subprocess
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "describe", "--always", "--dirty"], capture_output=True,
                             text=True, timeout=10)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def parse_budget(text: str) -> dict:
    """BUDGET with 'key=int,...' on top (a comparison of budgets; keys: `rounds` and LoopSettings' fields)."""
    out = dict(BUDGET)
    for item in filter(None, (text or "").split(",")):
        key, _, val = item.partition("=")
        try:
            out[key] = float(val) if key == "first_window" else int(val)
        except ValueError:
            out[key] = None
        if key not in BUDGET or out[key] is None or out[key] < 0:
            raise SystemExit(f"--budget: {item!r} is not KEY=NUMBER >= 0 with KEY one of {', '.join(BUDGET)}")
    return out


def cmd_run(args) -> int:
    logging.basicConfig(level=logging.ERROR)
    fams = [f for f in args.families.split(",") if f] if args.families else None
    amp_index = [int(i) for i in args.amplitudes_index.split(",")] if args.amplitudes_index else None
    todo = cases(args.part, args.records, fams, amp_index, args.syn_clean)
    if args.ids:   # these cases, in this order (a short run takes the most telling first)
        by_id = {c["id"]: c for c in todo}
        todo = [by_id[i] for i in args.ids.split(",") if i in by_id]
    budget, results = parse_budget(args.budget), Path(args.results)
    results.mkdir(parents=True, exist_ok=True)
    stamp, commit = code_stamp(), _commit()
    print(f"code stamp {stamp} (commit {commit})", flush=True)
    done = 0
    for case in todo:
        path = results / f"{case['id']}.json"
        if path.is_file():   # done: kept unless --stale and stored under another stamp
            if not args.stale or json.loads(path.read_text()).get("code_stamp") == stamp:
                continue
        try:
            res = run_case(case, budget)
        except Exception as exc:   # a case that cannot run is recorded, the benchmark goes on
            import traceback
            res = {**case, "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()}
        res.update(code_stamp=stamp, commit=commit)
        write_json_atomic(path, res)
        done += 1
        print(f"{case['id']}: {res.get('outcome', res.get('error'))} found {res.get('found')} "
              f"({res.get('wall_s', 0):.0f} s)", flush=True)
        if args.limit and done >= args.limit:
            break
    return 0


# ------------------------------------------------------------------------------------------ the report
def load_results(folder: Path = RESULTS) -> list:
    return [json.loads(p.read_text()) for p in sorted(Path(folder).glob("*.json"))]


def rate_interval(k: int, n: int, level: float = 0.95) -> list:
    """The exact (Clopper-Pearson) `level` interval of a rate seen k times in n records; [0, 1] for none."""
    if n <= 0:
        return [0.0, 1.0]
    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=level, method="exact")
    return [float(ci.low), float(ci.high)]


def summarise(results: list, families: dict = None, budget: dict = None) -> dict:
    """Rates from the stored rows: per family (default FAMILIES: name -> (unit, amplitudes, what)) and
    amplitude the records, hits, wrong effects and the exact 95 % interval of the hit rate; the smallest
    amplitude found in >= 90 % of >= 5 records with the lower end of its interval (what the records
    guarantee); the clean records' false alarms with the upper end of theirs."""
    clean = [r for r in results if r["kind"] == "clean" and "error" not in r]
    false = [r["id"] for r in clean if r["found"]]
    det = {}
    for fam, (unit, amps, what) in (FAMILIES if families is None else families).items():
        target = "sensor" if fam.startswith("sensor") else "wheel_oor" if fam.startswith("wheel_oor") else fam
        rows = []
        for ia, a in enumerate(amps):
            rs = [r for r in results if r["kind"] == "effect" and r["family"] == fam and r["amp_index"] == ia
                  and "error" not in r]
            hit = [r for r in rs if target in r["found"][:1]]
            wrong = [r for r in rs if r["found"] and target not in r["found"][:1]]
            rows.append({"amplitude": a, "records": len(rs), "found": len(hit), "wrong_effect": len(wrong),
                         "rate": len(hit) / len(rs) if rs else None, "ci95": rate_interval(len(hit), len(rs)),
                         "outcomes": {o: sum(r["outcome"] == o for r in rs) for o in
                                      ("confirmed", "undecided", "not in the catalogue", "nothing significant")}})
        ok = [row["amplitude"] for row in rows if row["rate"] is not None and row["records"] >= 5
              and row["rate"] >= 0.9]
        at = next((row for row in rows if ok and row["amplitude"] == min(ok)), None)
        det[fam] = {"unit": unit, "what": what, "rows": rows, "smallest_90": min(ok) if ok else None,
                    "smallest_90_lower": at["ci95"][0] if at else None}
    ooc = {}
    for name in OOC:
        rs = [r for r in results if r["kind"] == "ooc" and r["artefact"] == name and "error" not in r]
        ooc[name] = {"records": len(rs), "not_in_catalogue": sum(r["outcome"] == "not in the catalogue" for r in rs),
                     "confirmed": sum(bool(r["found"]) for r in rs),
                     "nothing": sum(r["outcome"] == "nothing significant" for r in rs)}
    errors = [r["id"] for r in results if "error" in r]
    cpu = [r["cpu_s"] for r in results if "cpu_s" in r]
    return {"clean": {"records": len(clean), "false_confirmations": false,
                      "false_rate_upper": rate_interval(len(false), len(clean))[1],
                      "outcomes": {o: sum(r["outcome"] == o for r in clean) for o in
                                   ("confirmed", "undecided", "not in the catalogue", "nothing significant")},
                      "by_source": {s: sum(r["source"] == s for r in clean) for s in
                                    sorted({r["source"] for r in clean} | {"synthetic", "rig"})},
                      "protocols": sorted({r.get("protocol", "release") for r in clean}),
                      "layouts": sorted({str(r.get("layout")) for r in clean})},
            "detection": det, "out_of_catalogue": ooc, "errors": errors,
            "cpu_s": {"total": float(sum(cpu)), "median": float(np.median(cpu)) if cpu else None},
            "budget": BUDGET if budget is None else budget}


def figure(summary: dict, path: Path, what: str = "release transient, layout 7") -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    fams = list(summary["detection"])
    ncol = 3
    fig, axes = plt.subplots(math.ceil(len(fams) / ncol), ncol, figsize=(12, 3.0 * math.ceil(len(fams) / ncol)))
    for ax, fam in zip(axes.ravel(), fams):
        d = summary["detection"][fam]
        xs = [row["amplitude"] for row in d["rows"] if row["records"]]
        ys = [100 * row["rate"] for row in d["rows"] if row["records"]]
        yw = [100 * row["wrong_effect"] / row["records"] for row in d["rows"] if row["records"]]
        ax.semilogx(xs, ys, "o-", color="tab:blue", label="the effect confirmed")
        ax.semilogx(xs, yw, "x--", color="tab:orange", label="another effect confirmed")
        ax.axhline(90, color="tab:red", ls="--", lw=1)
        ax.set_ylim(-5, 105)
        ax.set_title(fam, fontsize=10)
        # ticks at the amplitudes run: the log axis' minor labels overlap on short ranges
        ax.set_xticks(xs, [f"{x:g}" for x in xs], fontsize=8)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("fraction" if d["unit"] == "1" else d["unit"], fontsize=8)
        ax.set_ylabel("found, %", fontsize=8)
        ax.grid(alpha=0.3, which="both")
    axes.ravel()[0].legend(fontsize=7)
    for ax in axes.ravel()[len(fams):]:
        ax.axis("off")
    c = summary["clean"]
    code = summary.get("code")
    fig.suptitle(f"Closed loop: detection rate against amplitude ({what}); clean records: "
                 f"{len(c['false_confirmations'])} false confirmation(s) in {c['records']}"
                 + (f"\n{code['of_current']} of {code['rows']} rows on code {code['current']}"
                    + (" (only they counted)" if code.get("counted") == "current only" else "") if code else ""),
                 fontsize=10)
    fig.tight_layout()
    from lss_app.figures.save import save_figure
    save_figure(fig, path)


def table(summary: dict) -> str:
    n = max(len(d["rows"]) for d in summary["detection"].values())
    lines = ["| effect | unit | " + " | ".join(f"a{i}" for i in range(n))
             + " | smallest found in >= 90 % | its rate, 95 % interval (exact) |",
             "|---|---|" + "---|" * (n + 2)]
    for fam, d in summary["detection"].items():
        cells = [f"{row['amplitude']:g}: {row['found']}/{row['records']}"
                 + (f" ({row['wrong_effect']} wrong)" if row["wrong_effect"] else "") if row["records"]
                 else f"{row['amplitude']:g}: -" for row in d["rows"]]
        cells += [""] * (n - len(cells))   # a family with fewer amplitudes
        best = "-" if d["smallest_90"] is None else f"{d['smallest_90']:g}" + ("" if d["unit"] == "1" else f" {d['unit']}")
        ci = next((row["ci95"] for row in d["rows"] if row["amplitude"] == d["smallest_90"]), None) \
            if d["smallest_90"] is not None else None
        band = "-" if ci is None else f"{100 * ci[0]:.0f}-{100 * ci[1]:.0f} %"
        lines.append(f"| {fam} | {d['unit']} | " + " | ".join(cells) + f" | {best} | {band} |")
    c = summary["clean"]
    lines.append("")
    lines.append(f"Clean records: {len(c['false_confirmations'])} of {c['records']} with an effect confirmed; "
                 f"the false-alarm rate is below {100 * c['false_rate_upper']:.0f} % (95 %, exact).")
    return "\n".join(lines)


def code_of(results: list, stamp: str) -> dict:
    """Which rows are of the code `stamp` (the current one when reported), and which are not."""
    other = sorted(r["id"] for r in results if r.get("code_stamp") != stamp)
    return {"current": stamp, "of_current": len(results) - len(other), "rows": len(results), "other": other,
            "commits": sorted({r["commit"] for r in results if r.get("code_stamp") == stamp and r.get("commit")})}


def cmd_report(args) -> int:
    results, stamp = load_results(args.results), code_stamp()
    code = {**code_of(results, stamp), "counted": "current only" if args.current_only else "all rows"}
    if args.current_only:   # the rates of the current code alone (a rerun under way: its rows so far)
        results = [r for r in results if r.get("code_stamp") == stamp]
    s = summarise(results)
    s["code"] = code
    stored = Path(args.results).resolve() == RESULTS.resolve()
    if stored:   # the stored set's summary and figure; another folder only prints (or --figure)
        write_json_atomic(SUMMARY, s)
    fig = args.figure or (ROOT / "docs" / "figures" / "close_loop_rates.png" if stored else None)
    if fig:
        figure(s, Path(fig))
    print(json.dumps({k: s[k] for k in ("clean", "out_of_catalogue", "errors", "cpu_s")}, indent=1))
    c = s["code"]
    print(f"{c['of_current']} of {c['rows']} rows of the current code (stamp {c['current']}, commits "
          f"{', '.join(c['commits']) or '-'})" + (f"; the other {len(c['other'])} are from earlier code"
                                                  + (" and left out of the counts" if args.current_only else "")
                                                  if c["other"] else ""))
    print(table(s))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--part", choices=("clean", "detect", "ooc", "all"), default="all")
    r.add_argument("--records", type=int, default=10)
    r.add_argument("--families", default=None)
    r.add_argument("--amplitudes-index", default=None)
    r.add_argument("--limit", type=int, default=0, help="stop after this many new cases (0: all)")
    r.add_argument("--ids", default=None, help="only these case ids, in this order")
    r.add_argument("--syn-clean", type=int, default=SYN_CLEAN, help="synthetic clean records")
    r.add_argument("--budget", default="", help="KEY=N,... on top of BUDGET (e.g. base_evals=200); with --results "
                                                "elsewhere, so the stored set stays one budget's")
    r.add_argument("--results", default=str(RESULTS), help="folder of the case files")
    r.add_argument("--stale", action="store_true", help="rerun the cases stored under another code stamp")
    r.set_defaults(run=cmd_run)
    p = sub.add_parser("report")
    p.add_argument("--figure", default=None, help="default: docs/figures/close_loop_rates.png for the stored set")
    p.add_argument("--results", default=str(RESULTS), help="folder of the case files")
    p.add_argument("--current-only", action="store_true", help="count only the rows of the current code stamp")
    p.set_defaults(run=cmd_report)
    args = ap.parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    sys.exit(main())
