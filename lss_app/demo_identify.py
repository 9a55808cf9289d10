"""The stages of `make demo` after the plain simulation: a measurement of the
built-in layout 7 by the virtual transducer cart, the identification of its
four CoRs with Complex-RF, the report (identified against true values, the
paper's figures), and closing the loop on data with an undeclared effect
(lss_app.demo_close_loop)."""
from __future__ import annotations

import time
from pathlib import Path

from lss_fmu.atomic import write_json_atomic

MEASUREMENT = 20        # recovery set: layout 7, Table 3 row 20
WINDOW = 6.0            # s of the record used (the full lap is ~33 s)
BUDGET = 40             # Complex-RF evaluations


def run_stages(out: Path) -> list[str]:
    from lss_fmu.measurement import load_measurement
    from lss_fmu.rig import folder_name, load_truth, run_measurement
    from lss_fmu.runner import ChainSimulator

    from identification.identify import identify
    from identification.problem import from_measurement
    from lss_fmu.design import CORS, symbol

    from .figures.identification import forces_overlay, history, nrmsd_bars

    data = out / "data"
    print(f"[2] the virtual transducer cart: recovery measurement {MEASUREMENT} (layout 7) ...", flush=True)
    with ChainSimulator() as sim:
        info = run_measurement("recovery", MEASUREMENT, data, sim, lap_seconds=WINDOW + 2.0, overwrite=True)
    folder = data / folder_name(MEASUREMENT)
    meas = load_measurement(folder)
    truth = load_truth(folder)

    print(f"[3] identifying e_JA, e_JR, e_SW, e_RW with Complex-RF ({BUDGET} evaluations) ...", flush=True)
    cors = CORS
    problem = from_measurement(meas, "LW", free=cors, window=WINDOW)
    work = out / "identify"
    work.mkdir(parents=True, exist_ok=True)
    journal = work / "journal.jsonl"
    if journal.exists():
        journal.unlink()  # a demo starts afresh
    t0 = time.time()
    res = identify(problem, max_evals=BUDGET, seed=0, journal=journal, progress=True)
    write_json_atomic(work / "result.json", res.to_dict())
    initial, optimum = problem.simulate(res.x0), problem.simulate(res.x)
    forces_overlay(problem.times, problem.samples, initial, optimum, work / "forces", f"{meas.id}, LW")
    history(res.history_f, work / "history", f"{meas.id}, LW")
    nrmsd_bars(res.H0, res.H, work / "nrmsd", f"{meas.id}, LW")

    true = truth.get("cor", truth)
    rows = ["| CoR | true | start | identified |", "|---|---|---|---|"]
    for k, x0, x in zip(cors, res.x0, res.x):
        short = symbol(k)
        tv = true.get(short, true.get(k, float("nan"))) if isinstance(true, dict) else float("nan")
        rows.append(f"| {short} | {tv:.3f} | {x0:.3f} | {x:.3f} |")
    sections = [
        "## Measurement\n",
        f"Recovery measurement {MEASUREMENT} on layout 7 from the virtual transducer cart "
        f"({info['n_samples']} samples at 300 Hz, {info['wall_s']:.0f} s to make), in `data/`; "
        "the truth is in `data/answers/`, which identification never reads.\n",
        "## Identification\n",
        f"Contact model LW, the first {WINDOW:g} s of the record, Complex-RF with {BUDGET} evaluations "
        f"({time.time() - t0:.0f} s): f = {res.f0:.4g} at the start, {res.f:.4g} at the optimum "
        f"({res.message}).\n",
        "\n".join(rows) + "\n",
        "![forces](identify/forces.png)\n", "![history](identify/history.png)\n", "![nrmsd](identify/nrmsd.png)\n",
        "In steady running the chain is chaotic and the seven forces hardly constrain the CoRs "
        "(docs/identification.md): read the identified values with that in mind.\n",
    ]
    from .demo_close_loop import run_close_loop_stage
    return sections + run_close_loop_stage(out)


