"""`lss close-loop`: residual -> missing effect -> extended model, with the
report (identification.loop.close_loop; docs/close_loop.md).

    lss close-loop MEAS_DIR --model HW --out DIR [--settings TOML] [--base-result DIR] [--rounds 2]
                   [--effects a,b] [--window S] [--noise declared|estimate] [--seed S] [--workers N]

The base model is identified by the front door (`lss identify MEAS_DIR` with
the same settings: identification.pipeline.driver), its result written to
DIR/base/result.json, unless an earlier result is given. The record's
metadata says what to simulate: its protocol (steady, start-up, speed step,
stop, start-stop: from the chain at rest, or the photocell armed after the
protocol's run-in), layout, transducer cart and sensor (the declared noise
and zero tolerance). An expert's budgets live in the settings file: [identify]
for the base, [close_loop] for the loop (identification.loop.settings).
"""
from __future__ import annotations

import logging
from pathlib import Path


def register(sub, common) -> None:
    from identification.loop.catalogue import CATALOGUE
    ap = sub.add_parser("close-loop", parents=[common], help="residual -> missing effect -> extended model",
                        description="Close the loop: residual -> missing effect -> extended model.")
    ap.add_argument("measurement", help="measurement folder (samples.csv + meta.json)")
    ap.add_argument("--model", required=True, help="contact model: HC, HW, LW, LN, GZ or FL")
    ap.add_argument("--out", required=True, help="output folder (report.md, result.json, figures)")
    ap.add_argument("--settings", default=None, metavar="TOML",
                    help="an expert's settings file: [identify] for the base identification, [close_loop] for the "
                         "loop's budgets (default: the defaults)")
    ap.add_argument("--base-result", default=None,
                    help="result.json of an earlier `lss identify` of this measurement and model (skips the "
                         "base identification)")
    ap.add_argument("--rounds", type=int, default=2, help="rounds of the loop (each finds at most one effect)")
    ap.add_argument("--effects", default=None, help=f"candidate effects (default all: {','.join(CATALOGUE)})")
    ap.add_argument("--window", type=float, default=None, help="use only the first seconds of the record")
    ap.add_argument("--noise", choices=("declared", "estimate"), default="declared",
                    help="the force channels' noise for the tests: as declared in meta.json "
                         "(sensor.force_noise_std_N; estimated when not declared), or estimated from the residual")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--no-progress", action="store_true")
    ap.set_defaults(run=run)


def run(args) -> int:
    from identification.loop.catalogue import CATALOGUE
    from identification.loop.on_record import close_loop_record
    from identification.loop.settings import load_loop_settings
    from identification.pipeline.settings import load_settings
    from lss_fmu.design import parse_model
    from lss_fmu.measurement import load_measurement

    from .close_loop_report import write_report

    for name, v in (("--rounds", args.rounds), ("--workers", args.workers)):
        if v < 1:
            raise ValueError(f"{name} {v}: must be at least 1")
    effects = None
    if args.effects:
        effects = [e.strip() for e in args.effects.split(",") if e.strip()]
        bad = [e for e in effects if e not in CATALOGUE]
        if bad:
            raise ValueError(f"--effects: unknown {', '.join(bad)} (the catalogue: {', '.join(CATALOGUE)})")
    settings, loop_settings = load_settings(args.settings), load_loop_settings(args.settings)
    model = parse_model(args.model)
    meas = load_measurement(args.measurement)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(message)s",
                        filename=str(out / "close_loop.log"))
    res = close_loop_record(meas, model, out, settings=settings, loop_settings=loop_settings,
                            base=args.base_result, rounds=args.rounds, effects=effects, window=args.window,
                            noise=args.noise, seed=args.seed, workers=args.workers, progress=not args.no_progress,
                            on_base=lambda b: print(f"base: f = {b.f:.4g} ({b.message})"))
    report = write_report(res, out)
    problem = res.problem
    print(f"{meas.id}: {problem.protocol.name} record, layout {problem.layout}, {len(problem.times)} samples "
          f"({problem.times[-1]:.3g} s)")
    for r in res.rounds:
        print(f"round {r.number}: {r.verdict}")
    print(f"wrote {report} and {out / 'result.json'}")
    return 0
