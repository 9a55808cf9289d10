"""`lss identify REC [REC ...] --model M --out DIR`: records of one sorter
identified with one contact model by the method the records call for
(identification.pipeline.driver); the result file, the journal and the paper's
figures (8-11). An expert's knobs live in a settings file (--settings,
identification.pipeline.settings); the settings used are written into result.json."""
from __future__ import annotations

import logging
from pathlib import Path


def register(sub, common) -> None:
    ap = sub.add_parser("identify", parents=[common], help="identify the CoRs of one sorter from its records",
                        description="Identify the contact CoRs and the layout-dependent variables of one sorter "
                                    "from its records (several records of one sorter are fitted jointly). "
                                    "Transient records (start-up, start-stop, speed step, stop): the grown "
                                    "likelihood pipeline with an interval per variable; steady running: the "
                                    "force statistics, the CoRs reported not identifiable.")
    ap.add_argument("records", nargs="+", metavar="REC", help="measurement folders (samples.csv + meta.json) "
                    "of one sorter and protocol")
    ap.add_argument("--model", required=True, help="contact model: HC, HW, LW, LN, GZ or FL")
    ap.add_argument("--out", required=True, help="output folder (result.json, journal, figures); run again "
                    "after an interruption, it resumes")
    ap.add_argument("--settings", default=None, metavar="TOML",
                    help="an expert's settings file, table [identify] (identification.pipeline.settings; default: the "
                         "method of the recovery table)")
    ap.add_argument("--seed", type=int, default=0, help="the optimiser's seed (default 0)")
    ap.add_argument("--workers", type=int, default=1, help="local processes for simulations side by side: the complex's candidates, the Jacobians' "
                         "columns (default 1; the result is the same)")
    ap.add_argument("--survey", default=None, metavar="JSON",
                    help="a survey of the sorter (as-built track, cart mass, guide gap: lss_fmu.survey) given to "
                         "the FMU instead of the design drawing")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    ap.set_defaults(run=run)


def run(args) -> int:
    from identification.pipeline.driver import build_problem, identify_records
    from identification.pipeline.settings import load_settings
    from lss_fmu.atomic import write_json_atomic
    from lss_fmu.design import parse_model
    from lss_fmu.measurement import load_measurement
    from lss_fmu.survey import load_survey

    from .figures.identification import forces_overlay, history, nrmsd_bars

    if args.workers < 1:
        raise ValueError(f"--workers {args.workers}: must be at least 1")
    settings = load_settings(args.settings)
    model = parse_model(args.model)
    records = [load_measurement(d) for d in args.records]
    survey = None if args.survey is None else load_survey(args.survey)
    problem = build_problem(records, model, settings, survey=survey)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(message)s",
                        filename=str(out / "identify.log"))
    res = identify_records(records, model, settings, seed=args.seed, journal=out / "journal.jsonl",
                           progress=not args.no_progress, workers=args.workers, problem=problem, survey=survey)
    write_json_atomic(out / "result.json", res.to_dict())
    title = f"{records[0].id}, model {model}"
    rp = res.problem   # on the window the result is for
    joint = hasattr(rp, "parts")
    q = rp.parts[0] if joint else rp
    x0, x = (rp.part_x(0, res.x0), rp.part_x(0, res.x)) if joint else (res.x0, res.x)
    try:   # the figures: the first record, on the window the result is for
        initial = q.simulate(x0)
        optimum = q.simulate(x)
    except Exception as exc:  # figures of a failed point: measured only
        logging.warning("cannot simulate for the figures: %s", exc)
        initial = optimum = None
    forces_overlay(q.times, q.samples, initial, optimum, out / "forces", f"{title}: f {res.f:.4g}",
                   tare=q.tare, noise=q.noise)
    history(res.history_f, out / "history", title)
    nrmsd_bars(res.H0, res.H, out / "nrmsd", title)
    print(f"{problem.name} {model} ({q.protocol.name}, {res.method}): f {res.f0:.4g} -> {res.f:.4g} after "
          f"{res.nfev} evaluations ({res.message})")
    for iv in res.intervals or []:
        print(f"  {iv}")
    print(f"wrote {out / 'result.json'} and figures forces/history/nrmsd (.png, .svg)")
    return 0
