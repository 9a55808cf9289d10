#!/usr/bin/env python3
"""The FMU through fmpy against the C core alone, and identification speed.

* fmpy overhead: the same run (layout7, `--time` s from the start, 300 Hz
  communication, the 7 force channels read at every point) once through
  `lss_fmu.runner.ChainSimulator` (fmpy, fmi2DoStep + fmi2GetReal per point)
  and once through the core's own C master loop (`lss_chain_run`, no Python
  in the loop); overhead = CPU(fmpy) / CPU(core) - 1. Best of `--repeat`.
* evaluations per hour of a layout-7 identification: one evaluation is one
  lap (track length / v_ref = 65 m / 2 m/s = 32.5 s) through ChainSimulator
  at the default tolerance, as identification runs it.

Usage::

    .venv/bin/python benchmarks/bench_fmpy.py [--fmu build/LSSChain.fmu] [--lib liblsscore.so] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from bench_common import COMM, FORCE_IDX, RESOURCES, load_core, machine
from lss_fmu.variables import FORCE_CHANNELS


def core_run(lib_path, layout, t_end, tol):
    ffi, lib = load_core(lib_path)
    err = ffi.new("char[1024]")
    idx = ffi.new("int[]", FORCE_IDX)
    n = int(round(t_end / COMM))
    out = np.empty((n, len(FORCE_IDX)))
    t0 = time.process_time()
    p = lib.lss_params_new()
    lib.lss_params_set_string(p, b"layout.name", layout.encode())
    lib.lss_params_set(p, b"solver.tolerance", tol)
    c = lib.lss_chain_new(p, str(RESOURCES).encode(), err, 1024)
    lib.lss_params_free(p)
    if lib.lss_chain_run(c, COMM, n, idx, len(FORCE_IDX), ffi.cast("double *", ffi.from_buffer(out)), err, 1024):
        raise RuntimeError(ffi.string(err).decode())
    lib.lss_chain_free(c)
    return time.process_time() - t0, out


def fmpy_run(sim, layout, t_end, tol):
    t0 = time.process_time()
    df = sim.simulate(t_end, COMM, {"layout.name": layout}, FORCE_CHANNELS, tolerance=tol)
    return time.process_time() - t0, df[FORCE_CHANNELS].to_numpy()[1:]


def loop_cost(sim, layout, n=20000):
    """CPU per communication point of the master loop alone: ChainSimulator's
    calls (fmi2DoStep of zero length + fmi2GetReal of the 7 forces) with
    the model's work taken out, in the runner's fast form and through
    fmpy's wrappers."""
    import ctypes
    from fmpy.fmi2 import fmi2Real, fmi2ValueReference
    sim.start({"layout.name": layout})
    vrs = [sim.vr(o) for o in FORCE_CHANNELS]
    c_vr = (fmi2ValueReference * len(vrs))(*vrs)
    c_val = (fmi2Real * len(vrs))()
    val = np.frombuffer(c_val, dtype=np.float64)
    data = np.empty((n, len(vrs)))
    comp = sim.fmu.component
    out = {}
    raw = sim.fmu._functions
    for name, do_step, get_real in (("raw", raw["fmi2DoStep"], raw["fmi2GetReal"]),
                                    ("fmpy", sim.fmu.fmi2DoStep, sim.fmu.fmi2GetReal)):
        t0 = time.process_time()
        for k in range(n):
            do_step(comp, 0.0, 0.0, 1)
            get_real(comp, c_vr, len(vrs), c_val)
            data[k] = val
        out[name] = (time.process_time() - t0) / n
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fmu", default=None)
    ap.add_argument("--lib", default=None)
    ap.add_argument("--layout", default="layout7")
    ap.add_argument("--time", type=float, default=5.0)
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-lap", action="store_true")
    ap.add_argument("--label", default="current")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    from lss_fmu.runner import ChainSimulator
    res = dict(label=a.label, machine=machine(), layout=a.layout, time=a.time, tol=a.tol)
    with ChainSimulator(a.fmu) as sim:
        fmpy_run(sim, a.layout, 0.1, a.tol)  # warm-up
        cf, cc = [], []
        for _ in range(a.repeat):
            t, x = fmpy_run(sim, a.layout, a.time, a.tol)
            cf.append(t)
            t, y = core_run(a.lib, a.layout, a.time, a.tol)
            cc.append(t)
        same = float(np.max(np.abs(x - y)))
        n = int(round(a.time / COMM))
        res.update(cpu_fmpy=min(cf), cpu_core=min(cc), overhead=min(cf) / min(cc) - 1.0,
                   us_per_comm_point=(min(cf) - min(cc)) / n * 1e6, max_abs_diff_fmpy_core=same)
        print(f"{a.layout}, {a.time:g} s at 300 Hz, tol {a.tol:g}: fmpy {min(cf):.3f} s CPU, core {min(cc):.3f} s "
              f"-> overhead {100 * res['overhead']:.1f} % ({res['us_per_comm_point']:.1f} us per communication "
              f"point); outputs agree to {same:.2g} N")
        lc = loop_cost(sim, a.layout)
        core_per_point = min(cc) / n
        res.update(loop_us_raw=1e6 * lc["raw"], loop_us_fmpy=1e6 * lc["fmpy"], core_us_per_point=1e6 * core_per_point,
                   loop_overhead=lc["raw"] / core_per_point)
        print(f"master loop alone: {1e6 * lc['raw']:.2f} us per point as ChainSimulator runs it "
              f"({1e6 * lc['fmpy']:.2f} us through fmpy's wrappers) against {1e6 * core_per_point:.0f} us of core work "
              f"per point -> {100 * res['loop_overhead']:.2f} %")
        if not a.no_lap:
            sim.simulate(0.01, COMM, {"layout.name": "layout7"}, FORCE_CHANNELS, tolerance=a.tol)
            lap = float(sim.get("track.length")) / 2.0
            t0 = time.process_time()
            sim.simulate(lap, COMM, {"layout.name": "layout7", "drive.v_ref": 2.0}, FORCE_CHANNELS, tolerance=a.tol)
            cpu = time.process_time() - t0
            res.update(lap_time=lap, lap_cpu=cpu, evals_per_hour=3600.0 / cpu)
            print(f"layout7 lap ({lap:.1f} s at 2 m/s) through fmpy: {cpu:.2f} s CPU -> "
                  f"{3600 / cpu:.0f} evaluations per hour per core")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)
    return res


if __name__ == "__main__":
    main()
