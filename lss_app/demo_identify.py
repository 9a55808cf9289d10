"""The stages of `make demo` after the plain simulation: a start-stop
measurement of the built-in layout 7 by the virtual transducer cart, the
identification of the paper's ten design variables as `lss identify` does it
by default (identification.pipeline.driver, with an interval for each), the report (identified
against true values, the paper's figures), and closing the loop on data with
an undeclared effect (lss_app.demo_close_loop)."""
from __future__ import annotations

import time
from pathlib import Path

from lss_fmu.atomic import write_json_atomic

MEASUREMENT = 20        # recovery set: layout 7, Table 3 row 20
PROTOCOL = "start-stop"  # from standstill, braked 1 s later: the record that carries the CoRs best


def run_stages(out: Path) -> list[str]:
    from lss_fmu.design import symbol
    from lss_fmu.measurement import load_measurement
    from lss_fmu.rig import folder_name, load_truth, run_measurement, true_design_values
    from lss_fmu.runner import ChainSimulator

    from identification.pipeline.driver import build_problem, identify_records
    from identification.pipeline.settings import Settings

    from .figures.identification import forces_overlay, history, nrmsd_bars

    data = out / "data"
    print(f"[2] the virtual transducer cart: recovery measurement {MEASUREMENT} (layout 7), {PROTOCOL} ...",
          flush=True)
    with ChainSimulator() as sim:
        info = run_measurement("recovery", MEASUREMENT, data, sim, overwrite=True, protocol=PROTOCOL)
    folder = data / folder_name(MEASUREMENT)
    meas = load_measurement(folder)
    truth = load_truth(folder)

    settings = Settings()   # what `lss identify REC --model LW` runs
    print(f"[3] identifying the ten design variables as `lss identify` does by default: the first "
          f"{settings.window:g} s, the likelihood objective, the complex on the first {settings.first_window:g} s "
          f"({settings.max_evals} evaluations), Levenberg-Marquardt over growing windows, intervals ...", flush=True)
    problem = build_problem([meas], "LW", settings)
    work = out / "identify"
    work.mkdir(parents=True, exist_ok=True)
    journal = work / "journal.jsonl"
    for old in work.glob("journal*"):
        old.unlink()  # a demo starts afresh
    t0, c0 = time.time(), time.process_time()
    res = identify_records([meas], "LW", settings, seed=0, journal=journal, progress=True, problem=problem)
    cpu = time.process_time() - c0
    problem = res.problem   # the window the result is for
    write_json_atomic(work / "result.json", res.to_dict())
    true = true_design_values(truth)
    f_truth = problem([true[k] for k in problem.free])
    initial, optimum = problem.simulate(res.x0), problem.simulate(res.x)
    forces_overlay(problem.times, problem.samples, initial, optimum, work / "forces",
                   f"{meas.id}, LW: f {res.f:.4g}, at the truth {f_truth:.4g}", tare=problem.tare,
                   noise=problem.noise)
    history(res.history_f, work / "history", f"{meas.id}, LW")
    nrmsd_bars(res.H0, res.H, work / "nrmsd", f"{meas.id}, LW")

    ivs = {iv.name: iv for iv in (res.intervals or [])}
    rows = ["| variable | true | start | identified | 95 % interval |", "|---|---|---|---|---|"]
    for k, x0, x in zip(problem.free, res.x0, res.x):
        iv = ivs.get(k)
        cell = "-" if iv is None else (f"{iv.lower:.4g} .. {iv.upper:.4g}" if iv.identifiable
                                       else "not identifiable")
        rows.append(f"| {symbol(k)} | {true[k]:.4g} | {x0:.4g} | {x:.4g} | {cell} |")
    sections = [
        "## Measurement\n",
        f"Recovery measurement {MEASUREMENT} on layout 7 from the virtual transducer cart, protocol "
        f"{PROTOCOL}: the chain parked with the transducer cart at the trigger point, the drive's set point "
        f"stepped to {meas.meta.get('speed_nominal')} m/s at the start command and back to 0 "
        f"{meas.protocol.step_time:g} s later ({info['n_samples']} samples at 300 Hz), in `data/`; the truth "
        f"is in `data/answers/`, which identification never reads.\n",
        "## Identification\n",
        f"Contact model LW, the method `lss identify` takes by default for a transient record "
        f"(identification.pipeline.driver; settings in `identify/result.json`): the first "
        f"{float(problem.times[-1]):.3g} s of the record used, the likelihood objective (each force's RMSD "
        f"over the sensor's declared noise: about 7 when only the noise is left), the paper's ten design "
        f"variables free; {res.message}. {time.time() - t0:.0f} s wall, {cpu:.0f} CPU-s. "
        f"f = {res.f0:.4g} at the start, {res.f:.4g} at the optimum, {f_truth:.4g} at the truth "
        f"(what the sensor's noise leaves): {res.f / f_truth:.2f} x the floor.\n",
        "\n".join(rows) + "\n",
        "Intervals from the Jacobian at the optimum (identification/uncertainty.py); a variable whose "
        "interval spans more than 40 % of its range is reported as not identifiable.\n",
        "![forces](identify/forces.png)\n", "![history](identify/history.png)\n", "![nrmsd](identify/nrmsd.png)\n",
        "One record of this kind determines e_JA, e_SW and e_RW to about +-0.01-0.04 (2 sd) depending on "
        "the layout, e_JR not at all (docs/identification.md, \"What a record can tell\"): "
        "compare the identified CoRs with their intervals and the truth.\n",
    ]
    from .demo_close_loop import run_close_loop_stage
    return sections + run_close_loop_stage(out)


