#!/usr/bin/env python3
"""The field set through the closed loop (issue 7): what does it find?

The field set (lss rig --set field) is what a real test would give: the
truth is a contact law none of the candidates is (GZ), the carts' masses
differ from the nominal, the guides have another play and the track was
built with small irregularities; none of it is declared. Each measurement is
identified with a candidate law, then the loop analyses the residual, ranks
the catalogue and extends the model with the winner if it earns its place.

    .venv/bin/python benchmarks/bench_close_loop_field.py --measurements 20-22 \\
        --json benchmarks/results/close_loop_field.json

Measurements are made with a shortened record (--lap-seconds) and the loop
uses its first --window seconds; each measurement's loop writes its own
report under --work, atomically, and a finished one is not run again.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from identification.loop.close_loop import close_loop  # noqa: E402
from identification.loop.settings import LoopSettings  # noqa: E402
from lss_app.close_loop_report import write_report  # noqa: E402
from identification.objective.problem import from_measurement  # noqa: E402
from lss_fmu.atomic import write_json_atomic  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402
from lss_fmu.rig import folder_name, generate_set, load_truth, parse_numbers  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--measurements", default="20-22")
    ap.add_argument("--model", default="LW")
    ap.add_argument("--work", default="build/bench_close_loop_field")
    ap.add_argument("--lap-seconds", type=float, default=8.0)
    ap.add_argument("--window", type=float, default=4.0)
    ap.add_argument("--base-evals", type=int, default=150)
    ap.add_argument("--max-evals", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    work = Path(args.work)
    data = work / "field"
    numbers = parse_numbers(args.measurements)
    if not all((data / folder_name(n) / "meta.json").is_file() for n in numbers):  # made once, then reused
        generate_set("field", data, numbers, workers=args.workers, lap_seconds=args.lap_seconds, progress=False)
    rows = []
    for n in numbers:
        folder = data / folder_name(n)
        out = work / "loop" / folder_name(n)
        done = out / "result.json"
        if done.is_file():
            res = json.loads(done.read_text())
        else:
            meas = load_measurement(folder)
            problem = from_measurement(meas, args.model, window=args.window, tare=True)
            t0 = time.time()
            r = close_loop(problem, rounds=args.rounds,
                           settings=LoopSettings(base_evals=args.base_evals, max_evals=args.max_evals),
                           seed=0, out=out, workers=args.workers,
                           sensor_offset_std=(meas.meta.get("sensor") or {}).get("force_offset_std_N"))
            res = {**r.to_dict(), "wall_s": time.time() - t0}
            write_report(r, out)
            write_json_atomic(done, res)
        truth = load_truth(folder)
        rows.append({"measurement": n, "layout": res["layout"], "model": args.model, "found": res["found"],
                     "verdict": res["verdict"], "wall_s": res.get("wall_s", res.get("seconds")),
                     "f": [(r["f_base"], r["f_extended"]) for r in res["rounds"]],
                     "truth_field": {k: v for k, v in (truth.get("field_deviations") or {}).items()
                                     if isinstance(v, (int, float, str))}})
        print(f"m{n:02d} ({res['layout']}): found {res['found'] or 'nothing'}; {res['verdict']}", flush=True)
    if args.json:
        write_json_atomic(Path(args.json), {"args": vars(args), "results": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
