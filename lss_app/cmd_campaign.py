"""`lss campaign` (every sorter x every contact model through the front door,
locally or on a Dask cluster, resumable) and `lss report` (the paper's section 4 from it)."""
from __future__ import annotations

from pathlib import Path


def register(sub, common) -> None:
    ap = sub.add_parser("campaign", parents=[common], help="identify many sorters x contact models",
                        description="Every sorter x every contact model through the pipeline of `lss identify` "
                                    "(the same defaults), locally or on a Dask cluster, resumable. Measurement "
                                    "folders of one name under the DATA folders are the records of one sorter, "
                                    "fitted jointly; or a manifest names them.")
    ap.add_argument("data_dirs", nargs="*", metavar="DATA", help="folders of measurements (mNN/ with meta.json)")
    ap.add_argument("--models", default="HC,HW,LW,LN", help="contact models, comma-separated (default: the "
                    "paper's four)")
    ap.add_argument("--out", required=True, help="campaign folder; run again after an interruption, it resumes")
    ap.add_argument("--manifest", default=None, metavar="TOML",
                    help="a [sorters] table of name = [record folders] instead of DATA")
    ap.add_argument("--settings", default=None, metavar="TOML",
                    help="an expert's settings file, table [identify] (as lss identify)")
    ap.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler")
    ap.add_argument("--workers", type=int, default=2, help="local processes (without --scheduler)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--surveyed", action="store_true",
                    help="give the FMU each sorter's survey (DATA/survey/mNN.json: as-built track, cart mass, "
                         "guide gap) instead of the design drawing")
    ap.add_argument("--no-progress", action="store_true")
    ap.set_defaults(run=run_campaign)

    rp = sub.add_parser("report", parents=[common], help="the paper's section 4 from a campaign")
    rp.add_argument("campaign")
    rp.add_argument("--show", default=None, metavar="NAMES",
                    help="measurements drawn whole per law, comma-separated (default: each law's median-f one)")
    rp.set_defaults(run=run_report)


def run_campaign(args) -> int:
    from identification.pipeline.campaign import CampaignError, run_campaign as campaign
    from identification.pipeline.settings import load_settings
    if not args.data_dirs and args.manifest is None:
        raise CampaignError("give DATA folders or --manifest")
    models = [m for m in args.models.split(",") if m.strip()]
    results = campaign([Path(d) for d in args.data_dirs], models, Path(args.out),
                       settings=load_settings(args.settings), manifest=args.manifest, workers=args.workers,
                       scheduler=args.scheduler, seed=args.seed, progress=not args.no_progress,
                       surveyed=args.surveyed)
    print(f"{len(results)} identifications in {args.out}/results; `lss report {args.out}` makes the report")
    return 0


def run_report(args) -> int:
    from .campaign_report import write_report
    show = [m.strip() for m in args.show.split(",") if m.strip()] if args.show else None
    path = write_report(Path(args.campaign), show=show)
    print(f"wrote {path}")
    return 0
