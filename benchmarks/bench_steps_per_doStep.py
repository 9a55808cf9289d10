#!/usr/bin/env python3
"""The most internal steps (accepted + rejected) one 0.01 s fmi2DoStep takes
on each built-in layout, at the default tolerance, at 1e-10 and 1e-12, and
at the smallest solver.h_max (1e-6 s): what the step limit of dopri5.c must
leave room for (docs/robustness.md, "Step limit").

    .venv/bin/python benchmarks/bench_steps_per_doStep.py [layout,...]
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from fmi_util import Slave  # noqa: E402

from lss_fmu.layouts import builtin_layouts  # noqa: E402

CASES = [(None, 0.01, 0.3), (1e-10, 0.01, 0.3), (1e-12, 0.01, 0.3), (None, 1e-6, 0.02)]  # tolerance, h_max, span


def main() -> None:
    layouts = sys.argv[1].split(",") if len(sys.argv) > 1 else builtin_layouts()
    for lay in layouts:
        for tol, hmax, span in CASES:
            with Slave() as s:
                s.init({"layout.name": lay, "solver.h_max": hmax}, tolerance=tol)
                t, prev, worst, note, start = 0.0, 0, 0, "", time.time()
                while t < span - 1e-9:
                    status = s.call("doStep", t, 0.01)
                    t += 0.01
                    if status:
                        note = f"status {status} at {t:.2f} s: {s.last_error()[:90]}"
                        break
                    n = s.get("solver.n_steps") + s.get("solver.n_rejected")
                    worst, prev = max(worst, n - prev), n
                print(f"{lay} tolerance {tol} h_max {hmax}: most steps per 0.01 s {worst} "
                      f"({time.time() - start:.1f} s) {note}", flush=True)


if __name__ == "__main__":
    main()
