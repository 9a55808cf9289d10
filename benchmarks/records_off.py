"""Per record, S per sample at each result's own window and the records off
the declared noise there (growing.records_off: RETRY_Z sd of chi^2, no
margin), for a folder of bench_recovery's joint results: where
`identify_grown(restarts=...)` would ask for another seed.

    .venv/bin/python benchmarks/records_off.py \
        build/bench_recovery/start-stop/likelihood/grown/shrink/ten_free_k3_auto
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from identification.pipeline.growing import record_S, records_off  # noqa: E402
from identification.objective.joint import JointProblem  # noqa: E402
from identification.objective.problem import from_measurement  # noqa: E402
from identification.pipeline.windowing import truncated  # noqa: E402
from lss_fmu.measurement import load_measurement  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="a folder of mNN.json from bench_recovery --repeats K")
    ap.add_argument("--data", type=Path, default=Path("build/bench_recovery/start-stop"),
                    help="the work folder holding data/ and data_rK/")
    args = ap.parse_args(argv)
    files = sorted(args.folder.glob("m*.json"))
    if not files:
        raise SystemExit(f"{args.folder}: no mNN.json results")
    for f in files:
        r = json.loads(f.read_text())
        n, k = int(r["number"]), int(r.get("records", 1))
        parts = [from_measurement(load_measurement((args.data / ("data" if j == 0 else f"data_r{j}")) / f"m{n:02d}"),
                                  r.get("model", "LW"), window=2.5, tare=True, objective="likelihood")
                 for j in range(k)]
        try:
            p = parts[0] if k == 1 else JointProblem(parts)
            q = truncated(p, r["window_s"]) if r["window_s"] < float(p.times[-1]) - 1e-9 else p
            x = np.array([r["x"][v] for v in q.free])
            w = 1.0 / np.asarray(q.noise, float) ** 2
            sim = q.simulate(x)
            per, limit = record_S(q, sim, w)
            print(f"m{n:02d}  window {r['window_s']:.3g} s  S per sample by record "
                  f"{' '.join(f'{v:.3f}' for v in per)}  limit {limit:.3f}  off {records_off(q, sim, w)}", flush=True)
        finally:
            for pp in parts:
                pp.sim.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
