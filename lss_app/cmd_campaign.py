"""`lss campaign` (every measurement x every contact model, locally or on a
Dask cluster, resumable) and `lss report` (the paper's section 4 from it)."""
from __future__ import annotations

from pathlib import Path


def register(sub, common) -> None:
    ap = sub.add_parser("campaign", parents=[common], help="identify all measurements x models",
                        description="The campaign: every measurement x every contact model, in parallel.")
    ap.add_argument("data_dir")
    ap.add_argument("--models", default="HC,HW,LW,LN")
    ap.add_argument("--out", required=True)
    ap.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler")
    ap.add_argument("--workers", type=int, default=2, help="local processes (without --scheduler)")
    ap.add_argument("--max-evals", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--window", type=float, default=None, help="use only the first seconds of each record")
    ap.add_argument("--settle", type=float, default=None,
                    help="run-in before the photocell is armed, s (default: the record's protocol's)")
    ap.add_argument("--free", default=None, help="design variables to identify (default: all ten)")
    ap.add_argument("--restarts", type=int, default=0,
                    help="restart a converged complex around the best point up to N times (0: as published)")
    ap.add_argument("--objective", default="pointwise", choices=("pointwise", "statistics", "likelihood"),
                    help="pointwise: Eq. 10-12 (default); statistics: spectra and amplitude distributions; "
                         "likelihood: the residual over the declared noise")
    ap.add_argument("--presolve", type=int, default=0,
                    help="evaluations of a first complex with only the layout-dependent variables free (0: none)")
    ap.add_argument("--refine-evals", type=int, default=0,
                    help="simulations of the local refinement after the complex (0: none)")
    ap.add_argument("--staged", action="store_true",
                    help="the layout-dependent variables by Levenberg-Marquardt first, the complex on the CoRs, "
                         "then Levenberg-Marquardt on everything (identification.staged)")
    ap.add_argument("--grown", action="store_true",
                    help="the complex on the record's first 0.3 s (--max-evals), then Levenberg-Marquardt over "
                         "windows growing to the whole record (identification.identify_grown)")
    ap.add_argument("--shrink", action="store_true",
                    help="when a CoR is rough at the optimum (a record that turns chaotic) or the fit stays above "
                         "the noise, identify again on the first 1.5, 1.2, 1.0 s (identification.windowing)")
    ap.add_argument("--tare", action="store_true",
                    help="take out zero errors within 3 sigma of the transducer's declared offset")
    ap.add_argument("--no-progress", action="store_true")
    ap.set_defaults(run=run_campaign)

    rp = sub.add_parser("report", parents=[common], help="the paper's section 4 from a campaign")
    rp.add_argument("campaign")
    rp.set_defaults(run=run_report)


def run_campaign(args) -> int:
    from identification.campaign import run_campaign as campaign
    from lss_fmu.design import parse_free, parse_model
    models = [parse_model(m) for m in args.models.split(",") if m.strip()]
    free = parse_free(args.free) if args.free else None
    results = campaign(Path(args.data_dir), models, Path(args.out), workers=args.workers,
                       scheduler=args.scheduler, max_evals=args.max_evals, seed=args.seed,
                       window=args.window, settle=args.settle, free=free, progress=not args.no_progress,
                       tare=args.tare, restarts=args.restarts, presolve=args.presolve,
                       refine_evals=args.refine_evals, uncertainty=True, objective=args.objective,
                       staged=args.staged, shrink=args.shrink, grown=args.grown)
    print(f"{len(results)} identifications in {args.out}/results; `lss report {args.out}` makes the report")
    return 0


def run_report(args) -> int:
    from .campaign_report import write_report
    path = write_report(Path(args.campaign))
    print(f"wrote {path}")
    return 0
