#!/usr/bin/env python3
"""Memory of one FMU instance and its growth over many reset+simulate cycles.

The FMU allocates only through the allocateMemory/freeMemory callbacks of
fmi2Instantiate; here they count: bytes held by the instance after
initialisation (per layout), and the bytes still held after each of
`--cycles` cycles of fmi2Reset + parameters + initialisation + a short
simulation (`--steps` communication points at 300 Hz) through
lss_fmu.runner.ChainSimulator. Growth = held bytes at the last cycle minus
held bytes at the first; the process RSS is reported alongside.

Usage::

    .venv/bin/python benchmarks/bench_memory.py [--cycles 10000] [--fmu build/LSSChain.fmu] [--json out.json]
"""
from __future__ import annotations

import argparse
import ctypes
import json
import time

from bench_common import COMM, machine

libc = ctypes.CDLL(None)
libc.calloc.restype = ctypes.c_void_p
libc.calloc.argtypes = [ctypes.c_size_t, ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]


class Counter:
    def __init__(self):
        self.live = {}
        self.n_alloc = 0

    def calloc(self, n, size):
        p = libc.calloc(n, size)
        if p:
            self.live[p] = n * size
            self.n_alloc += 1
        return p

    def free(self, p):
        if p:
            self.live.pop(p, None)
            libc.free(p)

    @property
    def held(self):
        return sum(self.live.values())


def rss_kib():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS"):
                return int(line.split()[1])
    return -1


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fmu", default=None)
    ap.add_argument("--cycles", type=int, default=10000)
    ap.add_argument("--steps", type=int, default=3, help="communication points per cycle")
    ap.add_argument("--layouts", nargs="+", default=["layout7", "layout1", "layout3"])
    ap.add_argument("--label", default="current")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    from lss_fmu import runner
    cnt = Counter()
    runner.fmpy_calloc = cnt.calloc  # the runner wraps these into the FMI callbacks
    runner.fmpy_free = cnt.free
    res = dict(label=a.label, machine=machine(), instance_bytes={})
    with runner.ChainSimulator(a.fmu) as sim:
        base = cnt.held
        for lay in a.layouts:
            sim.start({"layout.name": lay})
            res["instance_bytes"][lay] = dict(carts=int(sim.get("chain.n_carts")), bytes=cnt.held,
                                             chain_bytes=cnt.held - base)
            print(f"{lay}: {sim.get('chain.n_carts')} carts, instance holds {cnt.held / 1024:.1f} KiB "
                  f"({(cnt.held - base) / sim.get('chain.n_carts'):.0f} B per cart beyond the bare instance)")
        trace = []
        t0 = time.process_time()
        for k in range(1, a.cycles + 1):
            sim.simulate(a.steps * COMM, COMM, {"layout.name": "layout7"}, ["transducer.joint.F_x"])
            if k == 1 or k % max(1, a.cycles // 10) == 0:
                trace.append((k, cnt.held, len(cnt.live), rss_kib()))
        cpu = time.process_time() - t0
    first, last = trace[0], trace[-1]
    res.update(cycles=a.cycles, steps=a.steps, cpu=cpu, trace=trace, growth_bytes=last[1] - first[1],
               growth_blocks=last[2] - first[2], rss_growth_kib=last[3] - first[3],
               rss_growth_after_first_tenth_kib=last[3] - trace[1][3] if len(trace) > 1 else None,
               live_after_close=cnt.held)
    print(f"{a.cycles} reset+simulate cycles (layout7, {a.steps} points each, {cpu:.1f} s CPU): held bytes "
          f"{first[1]} -> {last[1]} (growth {res['growth_bytes']} B, {res['growth_blocks']} blocks); "
          f"RSS {first[3]} -> {last[3]} KiB; after freeInstance {cnt.held} B held")
    for k, held, blocks, rss in trace:
        print(f"  cycle {k:6d}: {held} B in {blocks} blocks, RSS {rss} KiB")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)
    return res


if __name__ == "__main__":
    main()
