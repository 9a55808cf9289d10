"""`lss close-loop`: residual -> missing effect -> extended model, with the
report (identification.loop.close_loop; docs/close_loop.md).

    lss close-loop MEAS_DIR --model HW --out DIR [--base-evals N] [--first-window S] [--max-evals N]
                   [--window S] [--rounds 2] [--effects a,b] [--seed S] [--noise declared|estimate]

The record's metadata says what to simulate: its protocol (steady, start-up,
speed step, stop, start-stop: from the chain at rest, or the photocell armed after the
protocol's run-in), layout, transducer cart and sensor (the declared noise
and zero tolerance).
"""
from __future__ import annotations

import logging
from pathlib import Path


def register(sub, common) -> None:
    from identification.loop.catalogue import CATALOGUE
    from identification.loop.close_loop import (BASE_REFINE_EVALS, PROFILE_POINTS, REFINE_EVALS, RESCORE_EVALS,
                                           TEST_MAX)
    from identification.pipeline.growing import FIRST
    ap = sub.add_parser("close-loop", parents=[common], help="residual -> missing effect -> extended model",
                        description="Close the loop: residual -> missing effect -> extended model.")
    ap.add_argument("measurement", help="measurement folder (samples.csv + meta.json)")
    ap.add_argument("--model", required=True, help="contact model: HC, HW, LW, LN, GZ or FL")
    ap.add_argument("--out", required=True, help="output folder (report.md, result.json, figures)")
    ap.add_argument("--base-result", default=None,
                    help="result.json of an earlier `lss identify` of this measurement and model (skips the "
                         "base identification)")
    ap.add_argument("--base-evals", type=int, default=300,
                    help="evaluations of the base identification, counted in simulations of the whole record")
    ap.add_argument("--first-window", type=float, default=FIRST,
                    help="the base identification starts on the record's first S seconds and grows its window "
                         f"to the whole record (default {FIRST:g}; 0: the complex on the whole record)")
    ap.add_argument("--max-evals", type=int, default=200, help="evaluations of each extended identification")
    ap.add_argument("--free", default=None, help="base design variables, e.g. e_JA,e_JR,e_SW,e_RW (default all)")
    ap.add_argument("--window", type=float, default=None, help="use only the first seconds of the record")
    ap.add_argument("--fit-evals", type=int, default=RESCORE_EVALS,
                    help="evaluations fitting each of the top candidate effects alone (raised to what the "
                         "effect's complex needs)")
    ap.add_argument("--refine-evals", type=int, default=REFINE_EVALS,
                    help="simulations of the local (Levenberg-Marquardt) refinement ending each extended "
                         "identification (0: none)")
    ap.add_argument("--base-refine-evals", type=int, default=BASE_REFINE_EVALS,
                    help="simulations of the base's refinement to its own optimum before any test (0: none)")
    ap.add_argument("--profile-points", type=int, default=PROFILE_POINTS,
                    help="values at which the base's least-determined variable is scanned, the others refitted, "
                         "before any test, and in every extension identified again over growing windows "
                         "(0: no profile)")
    ap.add_argument("--candidates", type=int, default=TEST_MAX,
                    help="candidate effects taken through the extended identification and the tests per round")
    ap.add_argument("--noise", choices=("declared", "estimate"), default="declared",
                    help="the force channels' noise for the tests: as declared in meta.json "
                         "(sensor.force_noise_std_N; estimated when not declared), or estimated from the residual")
    ap.add_argument("--rounds", type=int, default=2, help="rounds of the loop (each finds at most one effect)")
    ap.add_argument("--effects", default=None, help=f"candidate effects (default all: {','.join(CATALOGUE)})")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--no-tare", action="store_true",
                    help="compare forces as logged (Eq. 10-12 as is); by default a zero error within 3 sigma of "
                         "the transducer's declared offset is taken out first")
    ap.add_argument("--no-progress", action="store_true")
    ap.set_defaults(run=run)


def run(args) -> int:
    from identification.loop.catalogue import CATALOGUE
    from identification.loop.close_loop import base_from_result, close_loop
    from identification.objective.problem import from_measurement
    from lss_fmu.atomic import write_json_atomic
    from lss_fmu.design import parse_free, parse_model
    from lss_fmu.measurement import load_measurement

    from .close_loop_report import write_report

    for name, v in (("--base-evals", args.base_evals), ("--max-evals", args.max_evals), ("--rounds", args.rounds),
                    ("--fit-evals", args.fit_evals), ("--candidates", args.candidates),
                    ("--workers", args.workers)):
        if v < 1:
            raise ValueError(f"{name} {v}: must be at least 1")
    for name, v in (("--refine-evals", args.refine_evals), ("--base-refine-evals", args.base_refine_evals),
                    ("--profile-points", args.profile_points), ("--first-window", args.first_window)):
        if not v >= 0:
            raise ValueError(f"{name} {v}: must be at least 0")
    effects = None
    if args.effects:
        effects = [e.strip() for e in args.effects.split(",") if e.strip()]
        bad = [e for e in effects if e not in CATALOGUE]
        if bad:
            raise ValueError(f"--effects: unknown {', '.join(bad)} (the catalogue: {', '.join(CATALOGUE)})")
    model = parse_model(args.model)
    meas = load_measurement(args.measurement)
    problem = from_measurement(meas, model, free=parse_free(args.free), window=args.window, tare=not args.no_tare)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(message)s",
                        filename=str(out / "close_loop.log"))
    x_base = None
    if args.base_result:
        x_base = base_from_result(args.base_result, problem)
    sensor = meas.meta.get("sensor") or {}
    res = close_loop(problem, x_base, effects=effects, rounds=args.rounds, base_evals=args.base_evals,
                     max_evals=args.max_evals, seed=args.seed, out=out, progress=not args.no_progress,
                     workers=args.workers, sensor_offset_std=sensor.get("force_offset_std_N"),
                     fit_evals=args.fit_evals, refine_evals=args.refine_evals,
                     base_refine_evals=args.base_refine_evals, test_max=args.candidates,
                     profile_points=args.profile_points, polish_evals=args.max_evals,
                     first_window=args.first_window or None,
                     noise_std=sensor.get("force_noise_std_N") if args.noise == "declared" else None)
    write_json_atomic(out / "result.json", res.to_dict())
    report = write_report(res, out)
    print(f"{meas.id}: {problem.protocol.name} record, layout {problem.layout}, {len(problem.times)} samples "
          f"({problem.times[-1]:.3g} s)")
    for r in res.rounds:
        print(f"round {r.number}: {r.verdict}")
    print(f"wrote {report} and {out / 'result.json'}")
    return 0
