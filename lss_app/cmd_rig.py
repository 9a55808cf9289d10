"""`lss rig`: generate the synthetic measurement sets (lss_fmu.rig).

    lss rig --set recovery|field|drawn --out DIR [--measurements 1,2,19-22]
            [--workers N] [--seed S] [--overwrite] [--fmu PATH] [--lap-seconds T]
            [--effects wheel_oor,sensor,...] [--effect-seed S] [--artefact channel_bump]
"""
from __future__ import annotations

import os
import sys


def register(sub, common) -> None:
    from lss_fmu import rig
    from lss_fmu.rig_effects import ARTEFACTS, CATALOGUE
    ap = sub.add_parser(
        "rig", parents=[common], help="synthesise measurements with the virtual transducer cart",
        description="Synthesise the paper's 22 transducer-cart measurements with the virtual transducer cart "
                    "(FMU + sensor model). Measurement folders go to DIR/mNN, the truth to DIR/answers/ "
                    "(never read by identification). See docs/measurements.md.")
    ap.add_argument("--set", required=True, choices=rig.SETS, dest="set_name",
                    help="recovery: LW truth with Table 3 CoRs; field: GZ truth, unequal cart mass, "
                         "as-built track; drawn: LW truth with CoRs drawn over the box from --seed")
    ap.add_argument("--out", required=True, metavar="DIR", help="output folder")
    ap.add_argument("--measurements", metavar="LIST", default=None,
                    help="subset, e.g. 1,2,19-22 (default: all 22; 9-11 are layout 3, the slow one)")
    ap.add_argument("--workers", type=int, default=None, metavar="N",
                    help="parallel processes (default: number of CPUs)")
    ap.add_argument("--seed", type=int, default=rig.DEFAULT_SEED, metavar="S",
                    help=f"seed of every random draw (default {rig.DEFAULT_SEED})")
    ap.add_argument("--overwrite", action="store_true",
                    help="make measurements again that are already in DIR (default: keep them, so an "
                         "interrupted run resumes)")
    ap.add_argument("--fmu", metavar="PATH", default=None, help="FMU to use (default build/LSSChain.fmu)")
    ap.add_argument("--lap-seconds", type=float, default=None, metavar="T",
                    help="log only T seconds instead of one lap (quick checks; such measurements are "
                         "marked as partial)")
    ap.add_argument("--effects", metavar="LIST", default=None,
                    help=f"undeclared effects to switch on in the FMU, comma separated, or all (known: "
                         f"{', '.join(CATALOGUE)}); drawn per layout from --effect-seed; meta.json says "
                         f"nothing, the truth goes to DIR/answers/ (docs/measurements.md, 'Undeclared effects')")
    ap.add_argument("--effect-seed", type=int, default=None, metavar="S",
                    help="seed of the effect and artefact draws (default: --seed)")
    ap.add_argument("--artefact", metavar="LIST", default=None,
                    help=f"artefacts outside the effects catalogue, added in the sensor stage (known: "
                         f"{', '.join(ARTEFACTS)})")
    ap.add_argument("--protocol", default="steady", choices=rig.PROTOCOLS,
                    help="what the sorter does while the cart logs (docs/measurements.md): steady running from "
                         "the photocell for a lap (default), a start-up from standstill at full thrust, a speed "
                         "step, a stop, a start-stop (a start braked after 1 s)")
    ap.add_argument("--repeat", type=int, default=0, metavar="K",
                    help="the K-th run of a start-up or start-stop on the same sorter: the chain parked "
                         "elsewhere, another noise draw (default 0; write each K into its own folder)")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    ap.set_defaults(run=run)


def run(args) -> int:
    """`lss rig`; returns the exit code (0 ok, 1 a measurement failed, 2 a usage error)."""
    from lss_fmu import rig
    from lss_fmu.rig_effects import parse_artefacts, parse_effects
    try:
        numbers = rig.parse_numbers(args.measurements)
        effects = parse_effects(args.effects, "--effects")
        artefacts = parse_artefacts(args.artefact, "--artefact")
    except ValueError as exc:
        print(f"lss rig: {exc}", file=sys.stderr)
        return 2
    if args.effects is not None and not effects:
        from lss_fmu.rig_effects import CATALOGUE
        print(f"lss rig: --effects: no effect named (known: {', '.join(CATALOGUE)}, or all)", file=sys.stderr)
        return 2
    if args.effect_seed is not None and not (effects or artefacts):
        print("lss rig: --effect-seed needs --effects or --artefact", file=sys.stderr)
        return 2
    if args.effect_seed is not None and args.effect_seed < 0:
        print(f"lss rig: --effect-seed {args.effect_seed}: must be 0 or more", file=sys.stderr)
        return 2
    if args.workers is not None and args.workers < 1:
        print(f"lss rig: --workers {args.workers}: must be at least 1", file=sys.stderr)
        return 2
    if args.lap_seconds is not None and not args.lap_seconds > 0:
        print(f"lss rig: --lap-seconds {args.lap_seconds}: must be positive", file=sys.stderr)
        return 2
    if args.fmu is not None and not os.path.isfile(args.fmu):
        print(f"lss rig: --fmu {args.fmu}: no such file", file=sys.stderr)
        return 2
    try:
        results = rig.generate_set(args.set_name, args.out, numbers, seed=args.seed, workers=args.workers,
                                   fmu=args.fmu, lap_seconds=args.lap_seconds, overwrite=args.overwrite,
                                   progress=not args.no_progress,
                                   log=lambda msg: print(msg, file=sys.stderr), effects=effects,
                                   effect_seed=args.effect_seed, artefacts=artefacts, protocol=args.protocol,
                                   repeat=args.repeat)
    except (FileExistsError, ValueError, OSError) as exc:
        print(f"lss rig: {exc}", file=sys.stderr)
        return 2
    failed = [r for r in results if "error" in r]
    print(f"{'meas':>4}  {'layout':8} {'samples':>8} {'wall s':>8} {'cpu s':>8}  status")
    for r in results:
        if "error" in r:
            status, samples, wall, cpu = r["error"], "", "", ""
        elif "skipped" in r:
            status, samples, wall, cpu = r["skipped"], "", "", ""
        else:
            status = "ok" if r["full_lap"] else "ok (partial lap)"
            samples, wall, cpu = str(r["n_samples"]), f"{r['wall_s']:.1f}", f"{r['cpu_s']:.1f}"
        print(f"{r['number']:>4}  {r.get('layout', ''):8} {samples:>8} {wall:>8} {cpu:>8}  {status}")
    if failed:
        print(f"lss rig: {len(failed)} measurement(s) failed; see above", file=sys.stderr)
        return 1
    return 0
