"""The integrator harness of benchmarks/bench_integrators.py: its replica of
the core's own Dormand-Prince pair, stepping the core's right-hand side
through lss_chain_put_state, must reproduce the core's run (else its figures
for the other methods would say nothing about the core)."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

from bench_common import COMM, nrmsd  # noqa: E402
from bench_integrators import Chain, integrate, tableau  # noqa: E402
from bench_throughput import Core  # noqa: E402


@pytest.fixture(scope="module")
def core():
    return Core()


def test_dp5_replica_reproduces_the_core(core):
    n = round(0.15 / COMM)
    c = core.new("layout7", 1e-4)
    start = core.save(c)
    s0 = core.stats(c)
    ref = core.run(c, n)
    core_steps = (core.stats(c) - s0)[0]
    core.load(c, start)
    ch = Chain(core, c)
    forces, steps, rejected = integrate(ch, tableau("dp5"), 1e-4, n)
    core.lib.lss_chain_free(c)
    assert np.all(np.isfinite(forces))
    assert abs(steps - core_steps) <= 0.03 * core_steps + 2
    # the same pair and weights; only the first step size differs
    assert nrmsd(forces, ref).max() < 2e-3


def test_put_state_accept_renormalises_and_reports_it(core):
    c = core.new("layout7", 1e-4)
    core.run(c, 3)
    ch = Chain(core, c)
    t, y = ch.state()
    assert not ch.put(t, y.copy(), True)  # the core's own accepted state: nothing to change
    y[3:7] *= 1.001  # cart 0's quaternion off unit length
    z = y.copy()
    assert not ch.put(t, z, False)
    assert np.array_equal(z, y)
    assert ch.put(t, z, True)
    assert np.linalg.norm(z[3:7]) == pytest.approx(1.0, abs=1e-12)
    scale, rel = ch.scale, ch.rel
    core.lib.lss_chain_free(c)
    assert scale.shape == y.shape and np.all(scale > 0) and set(np.unique(rel)) <= {0.0, 1.0}


def test_radau_path_runs_and_agrees_with_the_core(core):
    """The implicit path: its sparsity, grouped Jacobian and stepping on the
    communication points give the core's forces over a short window."""
    from bench_integrators import integrate_radau, sparsity

    n = round(0.05 / COMM)
    c = core.new("layout7", 1e-6)
    core.run(c, 30)
    start = core.save(c)
    ref = core.run(c, n)
    core.load(c, start)
    ch = Chain(core, c)
    pattern = sparsity(ch)
    # each cart couples with its neighbours only: far fewer entries than dense
    assert pattern.nnz < 0.05 * ch.n ** 2
    ch.n_rhs = 0
    forces, steps, _ = integrate_radau(ch, 1e-4, n, pattern)
    core.lib.lss_chain_free(c)
    assert steps >= n and ch.n_jac >= 1 and ch.n_rhs > steps
    assert nrmsd(forces, ref).max() < 1e-2
