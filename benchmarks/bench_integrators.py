#!/usr/bin/env python3
"""Would another explicit integrator need fewer right-hand sides? (issue 8)

The chain's own right-hand side (lss_chain_rhs) is driven from Python by
explicit Runge-Kutta pairs with the core's error weights (max norm,
lss_chain_error_scales), Hairer's PI step control, and what the core does
after every accepted step (lss_chain_put_state: contact onset memory,
projection warm starts, quaternion norm). Methods:

* dp5: Dormand-Prince 5(4), the core's own pair. It reproduces the core's
  step counts, which checks the harness;
* bs3: Bogacki-Shampine 3(2), 3 evaluations per step;
* dop853: Dormand-Prince 8(5,3), 12 evaluations per step, steps cut at the
  300 Hz communication points as the core's are;
* dop853-free: the same with steps not cut; the outputs come from its
  7th-order dense output (3 more evaluations in each step that holds a
  communication point);
* radau: Radau IIA of order 5 (implicit; scipy's, with the core's max norm
  and error weights), its Jacobian by grouped differences over the chain's
  sparsity (found once by perturbing each state; rows of the bookkeeping
  states, which feed nothing back, left out). Its evaluations include the
  Jacobians'; its linear algebra (sparse LU, real and complex) is not
  counted.

What is counted: right-hand sides per simulated second (what a method
changes; one evaluation costs what it costs in the core) and the restart
NRMSD of bench_throughput.py (pieces of --horizon s from the states of the
core at 1e-6). Python's own time is not measured: its loops, not the chain,
would dominate it.

The tableaux are scipy's (scipy.integrate._ivp), read at run time.

Usage::

    .venv/bin/python benchmarks/bench_integrators.py --layouts layout7 \\
        --runs core:1e-4 dp5:1e-4 dop853:1e-3 --json benchmarks/results/integrators.json
"""
from __future__ import annotations

import argparse
import json

import numpy as np
from scipy.integrate import Radau
from scipy.integrate._ivp import dop853_coefficients as D8
from scipy.integrate._ivp import radau as radau_module
from scipy.optimize._numdiff import group_columns
from scipy.sparse import csc_matrix
from scipy.integrate._ivp.rk import RK23, RK45, Dop853DenseOutput

from bench_common import COMM, FORCE_IDX, machine, nrmsd
from bench_throughput import Core
from lss_fmu.variables import VARIABLES

DEFAULT_RUNS = ["core:1e-4", "dp5:1e-4", "bs3:1e-4", "dop853:1e-3", "dop853:3e-3", "dop853:1e-2",
                "dop853-free:1e-3", "dop853-free:3e-3"]


def tableau(method: str) -> dict:
    """Butcher tableau, error weights and the controller's exponents."""
    if method == "dp5":
        return dict(A=RK45.A, B=RK45.B, C=RK45.C, E=RK45.E, alpha=0.2 - 0.75 * 0.04, beta=0.04)
    if method == "bs3":
        return dict(A=RK23.A, B=RK23.B, C=RK23.C, E=RK23.E, alpha=1 / 3 - 0.75 * 0.04, beta=0.04)
    if method == "radau":
        return dict(implicit=True)
    if method in ("dop853", "dop853-free"):
        return dict(A=D8.A[:12, :12], B=D8.B, C=D8.C[:12], E5=D8.E5, E3=D8.E3, alpha=1 / 8, beta=0.0,
                    free=method == "dop853-free")
    raise SystemExit(f"unknown method {method!r}: core, dp5, bs3, dop853, dop853-free, radau")


class Chain:
    """One chain's right-hand side and state through the core's flat API."""

    def __init__(self, core: Core, c):
        self.core, self.c, ffi, lib = core, c, core.ffi, core.lib
        self.n = lib.lss_chain_ny(c)
        self.scale, self.rel = np.empty(self.n), np.empty(self.n)
        lib.lss_chain_error_scales(c, self._p(self.scale), self._p(self.rel))
        self.n_rhs = self.n_jac = 0
        self._out = np.empty(len(VARIABLES))

    def _p(self, a):
        return self.core.ffi.cast("double *", self.core.ffi.from_buffer(a))

    def f(self, t, y):
        dy = np.empty(self.n)
        self.core.lib.lss_chain_rhs(self.c, t, self._p(np.ascontiguousarray(y)), self._p(dy))
        self.n_rhs += 1
        return dy

    def state(self):
        y = np.empty(self.n)
        self.core.lib.lss_chain_state(self.c, self._p(y))
        return self.core.lib.lss_chain_time(self.c), y

    def put(self, t, y, accept):
        """y as the state (renormalised in place with accept); True if f(t, y) changed."""
        return bool(self.core.lib.lss_chain_put_state(self.c, t, self._p(y), int(accept)))

    def forces(self):
        self.core.lib.lss_chain_outputs(self.c, self._p(self._out))
        return self._out[FORCE_IDX]


def integrate(ch: Chain, tab: dict, tol: float, n_comm: int):
    """From the chain's state over n_comm communication intervals; forces at
    each point [n_comm, 7] and (accepted, rejected) steps."""
    A, B, C = tab["A"], tab["B"], tab["C"]
    s, free = len(C), tab.get("free", False)
    t, y = ch.state()
    y = y.copy()
    ch.put(t, y, True)
    K = np.empty((16, ch.n))
    K[0] = ch.f(t, y)
    h, err_prev, steps, rejected = 1e-3, 1e-4, 0, 0
    forces, k_out = np.empty((n_comm, len(FORCE_IDX))), 0
    t0 = t
    while k_out < n_comm:
        t_next = t0 + (k_out + 1) * COMM
        t_end = t0 + n_comm * COMM if free else t_next
        h_prop = h
        last = t + h >= t_end - 1e-13
        hh = t_end - t if last else h
        while True:
            for i in range(1, s):
                K[i] = ch.f(t + C[i] * hh, y + hh * (A[i, :i] @ K[:i]))
            y_new = y + hh * (B @ K[:s])
            K[s] = ch.f(t + hh, y_new)
            den = tol * (ch.scale + ch.rel * np.maximum(np.abs(y), np.abs(y_new)))
            if "E" in tab:
                e = np.abs(hh * (tab["E"] @ K[:s + 1])) / den
            else:  # Hairer's DOP853 estimate: the 5th-order error, tempered by the 3rd
                e5, e3 = hh * (tab["E5"] @ K[:13]), hh * (tab["E3"] @ K[:13])
                d = np.sqrt(e5 ** 2 + 0.01 * e3 ** 2)
                e = np.abs(e5) * np.divide(np.abs(e5), d, out=np.zeros_like(d), where=d > 0) / den
            err = float(e.max()) if np.all(np.isfinite(e)) else np.inf
            fac11 = max(err, 1e-10) ** tab["alpha"]
            if err <= 1.0:
                break
            rejected += 1
            hh /= min(fac11 / 0.9, 5.0) if np.isfinite(err) else 4.0
            last = False
        fac = min(max(fac11 / err_prev ** tab["beta"] / 0.9, 0.2), 10.0)
        err_prev = max(err, 1e-4)
        t_old, y_old, t = t, y, (t_end if last else t + hh)
        y, steps = y_new, steps + 1
        h = max(min(hh / fac, h_prop), hh) if last else hh / fac
        if free:  # outputs at the communication points inside the step, by dense output
            inside = [t0 + (k + 1) * COMM for k in range(k_out, n_comm) if t0 + (k + 1) * COMM <= t + 1e-13]
            if inside:
                for i in range(13, 16):
                    K[i] = ch.f(t_old + D8.C[i] * hh, y_old + hh * (D8.A[i, :i] @ K[:i]))
                F = np.empty((7, ch.n))
                dy = y - y_old
                F[0], F[1], F[2] = dy, hh * K[0] - dy, 2 * dy - hh * (K[12] + K[0])
                F[3:] = hh * (D8.D @ K[:16])
                dense = Dop853DenseOutput(t_old, t, y_old, F)
                for tc in inside:
                    ch.put(tc, np.array(dense(tc)), False)
                    forces[k_out], k_out = ch.forces(), k_out + 1
        K[0] = ch.f(t, y) if ch.put(t, y, True) else K[s]
        if last and not free:
            forces[k_out], k_out = ch.forces(), k_out + 1
    return forces, steps, rejected


def sparsity(ch: Chain, dense_row: int = 80):
    """The Jacobian's pattern at the chain's state, by perturbing each state
    once; rows with more than dense_row entries (bookkeeping sums over all
    carts) are left out so that the columns can be grouped."""
    t, y = ch.state()
    f0, cols = ch.f(t, y), []
    for j in range(ch.n):
        yp = y.copy()
        yp[j] += 1e-7 * max(1.0, abs(yp[j]))
        cols.append(np.flatnonzero(ch.f(t, yp) != f0))
    rows = np.concatenate(cols)
    colidx = np.concatenate([np.full(len(r), j) for j, r in enumerate(cols)])
    keep = np.bincount(rows, minlength=ch.n)[rows] <= dense_row
    diag = np.arange(ch.n)
    rows, colidx = np.concatenate([rows[keep], diag]), np.concatenate([colidx[keep], diag])
    return csc_matrix((np.ones(len(rows)), (rows, colidx)), shape=(ch.n, ch.n))


def grouped_jacobian(ch: Chain, pattern):
    """J(t, y) by forward differences, one evaluation per group of columns
    that share no row (scipy's grouping), plus one at y."""
    coo = pattern.tocoo()
    rows, cols = coo.row, coo.col
    groups = group_columns(pattern)
    members = [np.flatnonzero(groups == g) for g in range(groups.max() + 1)]
    entries = [np.flatnonzero(groups[cols] == g) for g in range(len(members))]

    def jac(t, y):
        ch.n_jac += 1
        f0, data = ch.f(t, y), np.empty(len(rows))
        h = 1e-7 * np.maximum(1.0, np.abs(y))
        for cols_g, e in zip(members, entries):
            yp = y.copy()
            yp[cols_g] += h[cols_g]
            df = ch.f(t, yp) - f0
            data[e] = df[rows[e]] / h[cols[e]]
        return csc_matrix((data, (rows, cols)), shape=pattern.shape)

    return jac


def integrate_radau(ch: Chain, tol: float, n_comm: int, pattern):
    """scipy's Radau IIA with the core's max norm and weights, each step
    ending on the communication points as the core's do."""
    saved, radau_module.norm = radau_module.norm, lambda x: float(np.max(np.abs(x)))
    try:
        return _radau_run(ch, tol, n_comm, pattern)
    finally:
        radau_module.norm = saved


def _radau_run(ch: Chain, tol: float, n_comm: int, pattern):
    t0, y = ch.state()
    y = y.copy()
    ch.put(t0, y, True)
    s = Radau(ch.f, t0, y, t0 + COMM, rtol=tol, atol=tol * ch.scale, jac=grouped_jacobian(ch, pattern),
              first_step=1e-3)
    s.rtol = np.maximum(tol * ch.rel, 1e-13)  # per component, as the core's (the constructor takes a scalar)
    forces, steps = np.empty((n_comm, len(FORCE_IDX))), 0
    for k in range(n_comm):
        s.t_bound, s.status = t0 + (k + 1) * COMM, "running"
        while s.status == "running":
            msg = s.step()
            if s.status == "failed":
                raise RuntimeError(f"Radau failed at t = {s.t}: {msg}")
            steps += 1
            yy = s.y.copy()
            if ch.put(s.t, yy, True):
                s.y, s.f = yy, ch.f(s.t, yy)
        forces[k] = ch.forces()
    return forces, steps, 0


def measure(core: Core, layout: str, runs: list, settle: float, horizon: float, pieces: int) -> list:
    n_settle, n_hor = round(settle / COMM), round(horizon / COMM)
    c = core.new(layout, 1e-6)
    core.run(c, n_settle)
    states, ref = [], []
    for _ in range(pieces):
        states.append(core.save(c))
        ref.append(core.run(c, n_hor))
    core.lib.lss_chain_free(c)
    ref = np.vstack(ref)
    results = []
    for spec in runs:
        method, tol = spec.split(":")
        tol = float(tol)
        c = core.new(layout, tol)
        ch = Chain(core, c)
        pattern = None
        if method == "radau":
            core.load(c, states[0])
            pattern = sparsity(ch)
            ch.n_rhs = 0
        out, steps, rejected = [], 0, 0
        for buf in states:
            core.load(c, buf)
            if method == "core":
                s0 = core.stats(c)
                out.append(core.run(c, n_hor))
                st = core.stats(c) - s0
                steps, rejected, ch.n_rhs = steps + st[0], rejected + st[1], ch.n_rhs + st[2]
            else:
                tab = tableau(method)
                fo, a, r = (integrate_radau(ch, tol, n_hor, pattern) if tab.get("implicit")
                            else integrate(ch, tab, tol, n_hor))
                out.append(fo)
                steps, rejected = steps + a, rejected + r
        n_carts = core.lib.lss_chain_n_carts(c)
        core.lib.lss_chain_free(c)
        h = nrmsd(np.vstack(out), ref)
        sim = pieces * n_hor * COMM
        r = dict(layout=layout, carts=n_carts, method=method, tol=tol, rhs_per_s=ch.n_rhs / sim,
                 steps_per_s=float(steps) / sim, rejected_per_s=float(rejected) / sim,
                 jacobians_per_s=ch.n_jac / sim,
                 nrmsd_restart_max=float(h.max()), nrmsd_restart=[float(x) for x in h])
        print(f"{layout} {method:11s} tol {tol:.0e}: {r['rhs_per_s']:6.0f} rhs/s, {r['steps_per_s']:5.0f} steps/s, "
              f"{r['rejected_per_s']:4.0f} rejected/s{f', {ch.n_jac / sim:.0f} Jacobians/s' if ch.n_jac else ''}; NRMSD restart max {100 * h.max():.2f} % "
              f"(channels {' '.join(f'{100 * x:.2f}' for x in h)})", flush=True)
        results.append(r)
    return results


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--layouts", nargs="+", default=["layout7", "layout1", "layout3"])
    ap.add_argument("--runs", nargs="+", default=DEFAULT_RUNS, help="method:tolerance, method one of "
                    "core (the C core's DOPRI5), dp5, bs3, dop853, dop853-free, radau")
    ap.add_argument("--settle", type=float, default=1.0)
    ap.add_argument("--horizon", type=float, default=0.5, help="restart piece, s")
    ap.add_argument("--pieces", type=int, default=2)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    for spec in a.runs:
        if spec.split(":")[0] != "core":
            tableau(spec.split(":")[0])
    core = Core()
    print(machine())
    results = [r for lay in a.layouts for r in measure(core, lay, a.runs, a.settle, a.horizon, a.pieces)]
    out = dict(machine=machine(), settle=a.settle, horizon=a.horizon, pieces=a.pieces, results=results)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)
    return out


if __name__ == "__main__":
    main()
