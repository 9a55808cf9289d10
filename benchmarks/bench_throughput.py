#!/usr/bin/env python3
"""Throughput of the chain core (issue 8), with its accuracy.

For each layout (default: layout7, layout1, layout3 = 52, 171, 685 carts):

* throughput: cart-seconds simulated per CPU-second over a window of
  `--window` s after `--settle` s (untimed), stepping to every 300 Hz
  communication point and reading the outputs there, by the C core's own
  master loop (lss_chain_run: no Python in the timed loop);
* cost per cart and right-hand side (ns), steps and evaluations per
  simulated second; the scaling exponent of CPU time against carts;
* accuracy, the 7-channel NRMSD (largest channel; brief section 5, H_j)
  against a reference at a 100x tighter tolerance, two ways:
  - "restart": the window is cut into pieces of `--horizon` s; each piece
    starts from the reference's own state (lss_chain_state_save/load) and is
    compared with the reference over the piece. This is the solver's error.
  - "free": one continuous run against one continuous reference. The chain is
    chaotic (a 1e-9 m/s change of the initial speed grows to ~10 % in 3 s),
    so this measures the chaos as much as the solver; reported, not targeted.

Usage::

    .venv/bin/python benchmarks/bench_throughput.py                    # all three layouts
    .venv/bin/python benchmarks/bench_throughput.py --layouts layout7 --tol 1e-4
    .venv/bin/python benchmarks/bench_throughput.py --lib /path/liblsscore.so --json before.json

The figures go to stdout and, with --json, to a file that
benchmarks/bench_report.py turns into docs/benchmarks.md.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from bench_common import (COMM, FORCE_IDX, RESOURCES, load_core, machine, nrmsd_summary)

WINDOWS = {"layout7": 4.0, "layout1": 3.0, "layout3": 2.0}


class Core:
    def __init__(self, lib_path=None):
        self.ffi, self.lib = load_core(lib_path)
        self.err = self.ffi.new("char[1024]")
        self.idx = self.ffi.new("int[]", FORCE_IDX)

    def new(self, layout, tol, params=None):
        lib, ffi = self.lib, self.ffi
        p = lib.lss_params_new()
        lib.lss_params_set_string(p, b"layout.name", layout.encode())
        lib.lss_params_set(p, b"solver.tolerance", tol)
        for k, v in (params or {}).items():
            if lib.lss_params_set(p, k.encode(), float(v)):
                raise KeyError(k)
        c = lib.lss_chain_new(p, str(RESOURCES).encode(), self.err, 1024)
        lib.lss_params_free(p)
        if c == ffi.NULL:
            raise RuntimeError(ffi.string(self.err).decode())
        return c

    def run(self, c, n_comm):
        """Steps n_comm communication points; returns forces [n_comm, 7]."""
        out = np.empty((n_comm, len(FORCE_IDX)))
        if self.lib.lss_chain_run(c, COMM, n_comm, self.idx, len(FORCE_IDX),
                                  self.ffi.cast("double *", self.ffi.from_buffer(out)), self.err, 1024):
            raise RuntimeError(self.ffi.string(self.err).decode())
        return out

    def stats(self, c):
        st = self.ffi.new("long[3]")
        self.lib.lss_chain_stats(c, st)
        return np.array(list(st))

    def save(self, c):
        buf = np.empty(self.lib.lss_chain_state_size(c))
        self.lib.lss_chain_state_save(c, self.ffi.cast("double *", self.ffi.from_buffer(buf)))
        return buf

    def load(self, c, buf):
        self.lib.lss_chain_state_load(c, self.ffi.cast("double *", self.ffi.from_buffer(buf)))


def measure(core: Core, layout: str, tol: float, settle: float, window: float, horizon: float,
            params=None, accuracy=True, repeat=1, ref_tol=None) -> dict:
    n_settle, n_win, n_hor = (int(round(x / COMM)) for x in (settle, window, horizon))
    n_win = max(n_hor, n_win // n_hor * n_hor)
    # throughput (best of `repeat` runs)
    cpus = []
    for _ in range(repeat):
        c = core.new(layout, tol, params)
        core.run(c, n_settle)
        s0 = core.stats(c)
        t0 = time.process_time()
        forces = core.run(c, n_win)
        cpus.append(time.process_time() - t0)
        st = core.stats(c) - s0
        n = core.lib.lss_chain_n_carts(c)
        core.lib.lss_chain_free(c)
    cpu = min(cpus)
    sim = n_win * COMM
    res = dict(layout=layout, carts=n, tol=tol, settle=settle, window=sim, cpu=cpu,
               throughput=n * sim / cpu, steps_per_s=st[0] / sim, rejected_per_s=st[1] / sim,
               rhs_per_s=st[2] / sim, ns_per_cart_rhs=cpu / st[2] / n * 1e9)
    if not accuracy:
        return res
    # reference at tol/100: continuous, with its states at the restart points
    # the reference: the core's DOPRI5 (whatever method is measured) at ref_tol
    ref_tol = ref_tol or tol / 100
    ref_params = {k: v for k, v in (params or {}).items() if k != "solver.method"} or None
    c = core.new(layout, ref_tol, ref_params)
    core.run(c, n_settle)
    states, ref = [], []
    for k in range(n_win // n_hor):
        states.append(core.save(c))
        ref.append(core.run(c, n_hor))
    core.lib.lss_chain_free(c)
    ref = np.vstack(ref)
    free = nrmsd_summary(forces, ref)
    # restarts: each piece from the reference's state, at the tested tolerance
    pieces = []
    c = core.new(layout, tol, params)
    for k, buf in enumerate(states):
        core.load(c, buf)
        pieces.append(core.run(c, n_hor))
    core.lib.lss_chain_free(c)
    restart = nrmsd_summary(np.vstack(pieces), ref)
    res.update(ref_tol=ref_tol, horizon=n_hor * COMM, nrmsd_restart_max=restart[0], nrmsd_restart_rms=restart[1],
               nrmsd_free_max=free[0], nrmsd_free_rms=free[1])
    return res


def scaling(results: list) -> dict:
    """Exponent b of CPU per simulated second ~ carts^b, and the spread of
    the cost per cart-second around its mean."""
    n = np.array([r["carts"] for r in results], float)
    cost = np.array([r["cpu"] / r["window"] for r in results])
    if len(n) < 2:
        return {}
    b = np.polyfit(np.log(n), np.log(cost), 1)[0]
    per_cart = cost / n
    return dict(exponent=float(b), cost_per_cart_s=list(per_cart),
                spread=float(per_cart.max() / per_cart.min() - 1.0))


def repeated_layout(name: str, k: int, out_dir) -> str:
    """A layout that runs the built-in `name` k times over (the loop closes
    after each lap, so the k laps close too; the track lies on itself, which
    the model does not mind): the same mix of straights and curves and the
    same physics per cart, k times the carts and motors."""
    from pathlib import Path
    src = (RESOURCES / "layouts" / f"{name}.layout").read_text().splitlines()
    head, body = [], []
    for line in src:
        word = line.split("#")[0].split()
        if not word:
            continue
        if word[0] in ("straight", "curve", "vcurve", "spiral"):
            body.append(line)
        elif word[0] == "name":
            head.append(f"name {name}x{k}")
        elif word[0] == "motors":
            head.append(f"motors {int(word[1]) * k}")
        elif word[0] == "carts":
            head.append(f"carts {int(word[1]) * k}")
        else:
            head.append(line)
    path = Path(out_dir) / f"{name}x{k}.layout"
    path.write_text("\n".join(head + body * k) + "\n")
    return str(path)


def scaling_fixed_mix(core: Core, name: str, ks, tol: float, settle: float, window: float, repeat: int,
                      params=None) -> list:
    """Throughput of `name` repeated k times: cost against carts at a fixed
    mix of track elements (the built-in layouts differ in their share of
    curves, which costs more per cart than straight track). The pretension
    (the chain's total stretch) grows with k, so that every joint carries the
    same preload as in the single lap: the same physics per cart."""
    import tempfile
    from lss_fmu.variables import BY_NAME
    d0 = float(BY_NAME["chain.pretension"].start)
    out = []
    with tempfile.TemporaryDirectory() as d:
        for k in ks:
            r = measure(core, repeated_layout(name, k, d), tol, settle, window, 0.5,
                        params={**(params or {}), "chain.pretension": d0 * k}, accuracy=False, repeat=repeat)
            r["layout"] = f"{name}x{k}"
            print(fmt(r), flush=True)
            out.append(r)
    return out


def fmt(r: dict) -> str:
    s = (f"{r['layout']:8s} {r['carts']:4d} carts tol {r['tol']:.0e}: {r['throughput']:8.1f} cart-s/CPU-s "
         f"({r['cpu']:.2f} s CPU for {r['window']:.2f} s), {r['steps_per_s']:.0f} steps/s, "
         f"{r['rhs_per_s']:.0f} rhs/s, {r['ns_per_cart_rhs']:.0f} ns/cart/rhs")
    if "nrmsd_restart_max" in r:
        s += (f"\n{'':8s} NRMSD vs tol {r['ref_tol']:.0e}: restart ({r['horizon']:.2f} s pieces) "
              f"max {100 * r['nrmsd_restart_max']:.3f} % rms {100 * r['nrmsd_restart_rms']:.3f} %; "
              f"free max {100 * r['nrmsd_free_max']:.2f} % rms {100 * r['nrmsd_free_rms']:.2f} %")
    return s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--layouts", nargs="*", default=list(WINDOWS))
    ap.add_argument("--tol", type=float, nargs="+", default=[1e-4])
    ap.add_argument("--settle", type=float, default=1.0)
    ap.add_argument("--window", type=float, default=None, help="timed window, s (default per layout)")
    ap.add_argument("--horizon", type=float, default=0.5, help="restart piece, s")
    ap.add_argument("--repeat", type=int, default=1, help="timed runs per figure (best is kept)")
    ap.add_argument("--no-accuracy", action="store_true")
    ap.add_argument("--mix", default=None, help="also: scaling at a fixed mix, this layout repeated --mix-k times")
    ap.add_argument("--mix-k", type=int, nargs="+", default=[1, 2, 4, 8, 13])
    ap.add_argument("--mix-window", type=float, default=1.0)
    ap.add_argument("--ref-tol", type=float, default=None,
                    help="tolerance of the reference (default: tol / 100); the reference is always DOPRI5")
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE",
                    help="other parameters, e.g. solver.method=1 solver.vector_path=1 (issue 19)")
    ap.add_argument("--lib", default=None, help="core library to measure (default: build the current one)")
    ap.add_argument("--label", default="current")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    core = Core(a.lib)
    params = {kv.split("=", 1)[0]: float(kv.split("=", 1)[1]) for kv in a.set}
    print(machine())
    results = []
    for tol in a.tol:
        for lay in a.layouts:
            r = measure(core, lay, tol, a.settle, a.window or WINDOWS.get(lay, 2.0), a.horizon,
                        params=params or None, accuracy=not a.no_accuracy, repeat=a.repeat, ref_tol=a.ref_tol)
            r.update(params=params)
            print(fmt(r), flush=True)
            results.append(r)
    out = dict(label=a.label, machine=machine(), results=results)
    for tol in a.tol:
        sc = scaling([r for r in results if r["tol"] == tol])
        if sc:
            out.setdefault("scaling", {})[str(tol)] = sc
            print(f"tol {tol:.0e}: CPU ~ carts^{sc['exponent']:.3f}; cost per cart-second "
                  f"{', '.join(f'{1e3 * x:.2f} ms' for x in sc['cost_per_cart_s'])} (spread {100 * sc['spread']:.0f} %)")
    if a.mix:
        mix = scaling_fixed_mix(core, a.mix, a.mix_k, a.tol[0], a.settle, a.mix_window, a.repeat, params)
        sc = scaling(mix)
        out["mix"] = dict(layout=a.mix, tol=a.tol[0], results=mix, scaling=sc)
        print(f"{a.mix} repeated {a.mix_k} times, tol {a.tol[0]:.0e}: CPU ~ carts^{sc['exponent']:.3f}; cost per "
              f"cart-second {', '.join(f'{1e3 * x:.2f} ms' for x in sc['cost_per_cart_s'])} "
              f"(spread {100 * sc['spread']:.0f} %)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)
    return out


if __name__ == "__main__":
    main()
