"""`lss identify`: one measurement, one contact model, Complex-RF; the
result file, the journal and the paper's figures (8-11)."""
from __future__ import annotations

import logging
from pathlib import Path


REFINE_EVALS = 400   # Levenberg-Marquardt after the complex, at most: it stops once a step gains < 1e-4;
                     # 100 left m07's CoRs 0.034 off, 211 took them to 0.005 (benchmarks/bench_refine_budget.py)
MAX_EVALS = 5000     # the paper's limit
GROWN_EVALS = 400    # the complex on the first 0.3 s of --grown (docs/identification.md)


def register(sub, common) -> None:
    ap = sub.add_parser("identify", parents=[common], help="identify one measurement",
                        description="Identify one measurement with Complex-RF.")
    ap.add_argument("measurement", help="measurement folder (samples.csv + meta.json)")
    ap.add_argument("--with", dest="with_records", nargs="+", default=None, metavar="DIR",
                    help="further records of the same sorter (e.g. lss rig --repeat 1, 2 of a start-stop), "
                         "identified together with the first: the design shared, each record's trigger "
                         "point its own (identification.joint)")
    ap.add_argument("--model", required=True, help="contact model: HC, HW, LW, LN, GZ or FL")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--max-evals", type=int, default=None,
                    help=f"the complex's evaluations (default {MAX_EVALS}; with --grown {GROWN_EVALS}, on the "
                         f"first window)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1, help="parallel evaluations (Complex-RFP)")
    ap.add_argument("--free", default=None, help="design variables to identify, e.g. e_JA,e_JR,e_SW,e_RW "
                    "(default: all ten of Eq. 13)")
    ap.add_argument("--window", type=float, default=None, help="use only the first seconds of the record")
    ap.add_argument("--restarts", type=int, default=0,
                    help="restart a converged complex around the best point up to N times (0: as published); "
                         "with --grown: while a record stays off the noise at the chosen window, the whole "
                         "identification again with the next seed, up to N times, the better kept")
    ap.add_argument("--objective", default="pointwise", choices=("pointwise", "statistics", "likelihood"),
                    help="pointwise: the paper's Eq. 10-12 (default); statistics: spectra and amplitude "
                         "distributions per channel, for steady running; likelihood: the residual over the "
                         "sensor's declared noise, for transient records (docs/identification.md)")
    ap.add_argument("--presolve", type=int, default=0,
                    help="evaluations of a first complex with only the layout-dependent variables free (0: none)")
    ap.add_argument("--staged", action="store_true",
                    help="Levenberg-Marquardt on the layout-dependent variables first (--presolve simulations, "
                         "default 80), the complex on the CoRs alone, then Levenberg-Marquardt on everything "
                         "(identification.staged; pointwise or likelihood objective)")
    ap.add_argument("--grown", action="store_true",
                    help="the complex on the record's first 0.3 s (--max-evals evaluations there), its profile, "
                         "then Levenberg-Marquardt over windows growing to the whole record; with --shrink a "
                         "shorter window is taken up from the grown point at its length "
                         "(identification.identify_grown; pointwise or likelihood objective)")
    ap.add_argument("--start", default=None, choices=("complex", "single", "auto"),
                    help="with --grown and --with: where the joint fit starts; complex: over every variable on "
                         "the records' first window; single: the first record alone, then each "
                         "further record's trigger point (identification.joint_start); auto: the complex, and where "
                         "its first window stays above the declared noise the single start too, the better going on "
                         "(default)")
    ap.add_argument("--refine-evals", type=int, default=REFINE_EVALS,
                    help=f"simulations of the local refinement after the complex (default {REFINE_EVALS}; 0: none)")
    ap.add_argument("--shrink", action="store_true",
                    help="when a CoR is rough at the optimum (a record that turns chaotic) or the fit stays above "
                         "the noise, identify again on the first 1.5, 1.2, 1.0 s (identification.windowing)")
    ap.add_argument("--tare", action="store_true",
                    help="take out zero errors within 3 sigma of the transducer's declared offset")
    ap.add_argument("--no-progress", action="store_true")
    ap.set_defaults(run=run)


def run(args) -> int:
    from identification.staged import run as identify_or_staged
    from identification.problem import from_measurement
    from lss_fmu.atomic import write_json_atomic
    from lss_fmu.design import parse_free, parse_model
    from lss_fmu.measurement import load_measurement

    from .figures.identification import forces_overlay, history, nrmsd_bars

    if args.restarts < 0:
        raise ValueError(f"--restarts {args.restarts}: must be 0 or more")
    if args.max_evals is None:
        args.max_evals = GROWN_EVALS if args.grown else MAX_EVALS
    if args.max_evals < 1:
        raise ValueError(f"--max-evals {args.max_evals}: must be at least 1")
    if args.workers < 1:
        raise ValueError(f"--workers {args.workers}: must be at least 1")
    if args.refine_evals < 0:
        raise ValueError(f"--refine-evals {args.refine_evals}: must be 0 or more")
    if args.start not in (None, "complex") and not (args.grown and args.with_records):
        raise ValueError(f"--start {args.start}: where a joint fit starts, needs --grown and --with")
    model = parse_model(args.model)
    meas = load_measurement(args.measurement)
    problem = from_measurement(meas, model, free=parse_free(args.free), window=args.window, tare=args.tare,
                               objective=args.objective)
    first = problem
    if args.with_records:
        from identification.joint import JointProblem
        problem = JointProblem([first] + [
            from_measurement(load_measurement(d), model, free=parse_free(args.free), window=args.window,
                             tare=args.tare, objective=args.objective) for d in args.with_records])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(message)s",
                        filename=str(out / "identify.log"))
    if args.staged and args.grown:
        raise ValueError("--staged and --grown: choose one pipeline")
    more = {"start": args.start or "auto"} if args.grown else {}
    res = identify_or_staged(problem, args.staged, args.shrink, args.grown, max_evals=args.max_evals, seed=args.seed,
                             journal=out / "journal.jsonl", progress=not args.no_progress, workers=args.workers,
                             restarts=args.restarts, refine_evals=args.refine_evals, uncertainty=True,
                             presolve=args.presolve, **more)
    write_json_atomic(out / "result.json", res.to_dict())
    title = f"{meas.id}, model {model}"
    x0, x = (res.x0, res.x) if problem is first else (problem.part_x(0, res.x0), problem.part_x(0, res.x))
    try:   # the figures: the first record
        initial = first.simulate(x0)
        optimum = first.simulate(x)
    except Exception as exc:  # figures of a failed point: measured only
        logging.warning("cannot simulate for the figures: %s", exc)
        initial = optimum = None
    forces_overlay(first.times, first.samples, initial, optimum, out / "forces", title)
    history(res.history_f, out / "history", title)
    nrmsd_bars(res.H0, res.H, out / "nrmsd", title)
    print(f"{problem.name} {model} ({problem.protocol.name}): f {res.f0:.4g} -> {res.f:.4g} after {res.nfev} "
          f"evaluations ({res.replayed} from the journal; {res.message})")
    for iv in res.intervals or []:
        print(f"  {iv}")
    print(f"wrote {out / 'result.json'} and figures forces/history/nrmsd (.png, .svg)")
    return 0
