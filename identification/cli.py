"""`lss identify`, `lss campaign`, `lss report`, `lss close-loop`.

Errors the user can fix (a missing folder, a malformed measurement, an
unknown model, an impossible bound) surface as exceptions with a clear
message; `lss_fmu.cli.main` prints them as one line and exits non-zero.
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np

from lss_fmu.atomic import write_json_atomic
from lss_fmu.variables import CONTACT_MODELS

from .problem import DESIGN, SHORT


def _model(name: str) -> str:
    m = name.strip().upper()
    if m not in CONTACT_MODELS:
        raise ValueError(f"unknown contact model {name!r}: use one of {', '.join(CONTACT_MODELS)}")
    return m


def _free(text: str | None) -> tuple:
    if not text:
        return tuple(DESIGN)
    by_short = {v: k for k, v in SHORT.items()}
    out = []
    for item in text.split(","):
        item = item.strip()
        name = by_short.get(item, item)
        if name not in DESIGN:
            raise ValueError(f"--free {item!r}: not a design variable ({', '.join(SHORT.values())})")
        out.append(name)
    return tuple(out)


def identify_main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="lss identify", description="Identify one measurement with Complex-RF.")
    ap.add_argument("measurement", help="measurement folder (samples.csv + meta.json)")
    ap.add_argument("--model", required=True, help="contact model: HC, HW, LW, LN, GZ or FL")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--max-evals", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1, help="parallel evaluations (Complex-RFP)")
    ap.add_argument("--free", default=None, help="design variables to identify, e.g. e_JA,e_JR,e_SW,e_RW "
                    "(default: all ten of Eq. 13)")
    ap.add_argument("--window", type=float, default=None, help="use only the first seconds of the record")
    ap.add_argument("--restarts", type=int, default=0,
                    help="restart a converged complex around the best point up to N times (0: as published)")
    ap.add_argument("--tare", action="store_true",
                    help="take out zero errors within 3 sigma of the transducer's declared offset")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)

    from lss_fmu.measurement import load_measurement
    from .figures import forces_overlay, history, nrmsd_bars
    from .identify import identify
    from .problem import from_measurement

    if args.restarts < 0:
        raise ValueError(f"--restarts {args.restarts}: must be 0 or more")
    if args.max_evals < 1:
        raise ValueError(f"--max-evals {args.max_evals}: must be at least 1")
    model = _model(args.model)
    meas = load_measurement(args.measurement)
    problem = from_measurement(meas, model, free=_free(args.free), window=args.window, tare=args.tare)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(message)s",
                        filename=str(out / "identify.log"))
    res = identify(problem, max_evals=args.max_evals, seed=args.seed, journal=out / "journal.jsonl",
                   progress=not args.no_progress, workers=args.workers, restarts=args.restarts)
    write_json_atomic(out / "result.json", res.to_dict())
    title = f"{meas.id}, model {model}"
    try:
        initial = problem.simulate(res.x0)
        optimum = problem.simulate(res.x)
    except Exception as exc:  # figures of a failed point: measured only
        logging.warning("cannot simulate for the figures: %s", exc)
        initial = optimum = None
    forces_overlay(problem.times, problem.samples, initial, optimum, out / "forces", title)
    history(res.history_f, out / "history", title)
    nrmsd_bars(res.H0, res.H, out / "nrmsd", title)
    vals = ", ".join(f"{SHORT[k]}={v:.4g}" for k, v in zip(problem.free, res.x))
    print(f"{meas.id} {model}: f {res.f0:.4g} -> {res.f:.4g} after {res.nfev} evaluations "
          f"({res.replayed} from the journal; {res.message}); {vals}")
    print(f"wrote {out / 'result.json'} and figures forces/history/nrmsd (.png, .svg)")
    return 0


def _module_main(name: str):
    """The `main(argv)` of identification.<name>, imported when called."""
    def run(argv: list[str]) -> int:
        mod = __import__(f"identification.{name}", fromlist=["main"])
        return mod.main(argv)
    return run


campaign_main = _module_main("campaign")
report_main = _module_main("report")
close_loop_main = _module_main("close_loop")
