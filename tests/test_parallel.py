"""Simulations side by side (identification.objective.parallel): a
Jacobian's columns on local processes or a Dask cluster are the serial
ones bit for bit, and so is a whole identification with workers."""
from __future__ import annotations

import numpy as np
import pytest

from identification import Settings, identify_records
from identification.objective.jacobian import jacobian, one_sided_jacobian
from identification.objective.parallel import Failed, pooled, simulate_all
from identification.pipeline.driver import build_problem

SMALL = Settings(window=1.1, first_window=0.2, max_evals=12, refine_evals=30, restarts=0, shrink=False,
                 free=("contact.e_JA", "contact.e_SW", "contact.e_RW", "chain.pretension", "trigger.s_M"))


@pytest.fixture(scope="module")
def records(rig_record):
    return [rig_record(21, "start-stop", 1.1, repeat=k) for k in range(2)]


def _columns(problem, x):
    y0 = problem.simulate(x)
    return jacobian(problem, x, y0, weights=1.0 / problem.noise ** 2), one_sided_jacobian(problem, x, y0)


def _same(a, b) -> bool:
    (J1, used1, rough1), cols1 = a
    (J2, used2, rough2), cols2 = b
    return (np.array_equal(J1, J2) and np.array_equal(used1, used2) and np.array_equal(rough1, rough2)
            and len(cols1) == len(cols2) and all(np.array_equal(c, d) for c, d in zip(cols1, cols2)))


@pytest.fixture(scope="module")
def point(records):
    p = build_problem(records, "LW", SMALL)
    x = p.x0_vector()
    x[p.free.index("contact.e_JA")] = p.bounds["contact.e_JA"][1]   # one column at its bound: steps inwards
    return x


@pytest.fixture(scope="module")
def serial(records, point):
    return _columns(build_problem(records, "LW", SMALL), point)


def test_a_jacobian_on_local_processes_is_the_serial_one(records, point, serial):
    p = build_problem(records, "LW", SMALL)
    with pooled(p, workers=2) as q:
        assert q.pool is not None and all(part.pool is q.pool for part in q.parts)
        par = _columns(q, point)
    assert p.pool is None
    assert _same(serial, par)


def test_a_jacobian_on_a_dask_cluster_is_the_serial_one(records, point, serial):
    from dask.distributed import Client, LocalCluster
    p = build_problem(records, "LW", SMALL)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        with pooled(p, executor=client.get_executor()) as q:
            par = _columns(q, point)
    assert _same(serial, par)


def test_a_failed_simulation_comes_back_as_failed_on_a_worker_too(records, point):
    p = build_problem(records[:1], "LW", SMALL)
    bad = np.array(point[:p.dim], float)
    bad[p.free.index("trigger.s_M")] = np.nan   # no FMU takes it
    with pooled(p, workers=2) as q:
        out = simulate_all(q, [bad, np.array(point[:p.dim], float)])
    assert isinstance(out[0], Failed) and isinstance(out[1], np.ndarray)


def test_an_identification_with_workers_is_the_serial_one(records):
    small = Settings(window=0.6, first_window=0.2, max_evals=10, refine_evals=12, restarts=0, shrink=False,
                     free=("contact.e_SW", "contact.e_RW"))
    one = identify_records(records, "LW", small, workers=1)
    two = identify_records(records, "LW", small, workers=2)
    assert np.array_equal(one.x, two.x) and one.f == two.f and one.nfev == two.nfev
    assert [iv.to_dict() for iv in one.intervals] == [iv.to_dict() for iv in two.intervals]
    assert two.problem.pool is None
