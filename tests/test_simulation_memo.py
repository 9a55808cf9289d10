"""A simulation is a function of what it is run with (problem.simulate's
memo): asked again with the same values it is not run again, and the answer
is bit for bit the one a fresh run gives; anything it depends on changing
runs it again; a joint problem's Jacobian column of one record's trigger
point runs that record alone."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from identification import Settings
from identification.objective import problem as P
from identification.objective.jacobian import jacobian
from identification.objective.joint import own
from lss_fmu.design import TRIGGER
from identification.pipeline.driver import build_problem


@pytest.fixture(scope="module")
def records(rig_record):
    return [rig_record(20, "start-stop", 1.1, repeat=k) for k in range(2)]


@pytest.fixture
def runs(monkeypatch):
    """The runs of the FMU, as (record name, design vector) per run."""
    log = []
    run = P.IdentificationProblem.run

    def counted(self, x, *a, **k):
        log.append((self.name, tuple(np.round(np.asarray(x, float), 12))))
        return run(self, x, *a, **k)
    monkeypatch.setattr(P.IdentificationProblem, "run", counted)
    return log


def test_the_same_values_are_simulated_once_and_give_a_fresh_runs_answer(records, runs):
    p = build_problem(records[:1], "LW", Settings())
    x = p.x0_vector()
    y = p.simulate(x)
    y[:] = 0.0                     # the caller's copy: what is kept is not touched
    again = p.simulate(x)
    assert len(runs) == 1
    fresh = build_problem(records[:1], "LW", Settings())
    assert np.array_equal(again, fresh.simulate(x))
    assert len(runs) == 2


def test_anything_a_simulation_depends_on_changing_runs_it_again(records, runs):
    p = build_problem(records[:1], "LW", Settings())
    x = p.x0_vector()
    p.simulate(x)
    x2 = x.copy()
    x2[0] += 0.01
    p.simulate(x2)                                    # another design
    p.fixed["solver.h_max"] = 0.005                      # a fixed value changed in place
    p.simulate(x)
    p.tolerance = 3e-6                                # the solver
    p.simulate(x)
    p.simulate(x, extra={"effects.wheel_oor.amplitude": 1e-5})  # a further FMU value
    assert len(runs) == 5
    # a copy for another process starts with nothing kept
    q = pickle.loads(pickle.dumps(p))
    assert len(q._memo) == 0 and len(p._memo) == 5


def test_a_joint_jacobians_trigger_column_runs_only_its_own_record(records, runs):
    p = build_problem(records, "LW", Settings())
    x = p.x0_vector()
    y0 = p.simulate(x)
    assert len(runs) == 2
    k = p.free.index(own(1))
    lo, hi = np.array(p.bounds_array, float).T
    steps = 0.02 * (hi - lo)
    del runs[:]
    J, used, _ = jacobian(p, x, y0, steps=steps, exact=False)   # every column differenced
    t = p.parts[1].free.index(TRIGGER)
    base = p.part_x(1, x)[t]
    moved = [name for name, xr in runs if name == p.parts[1].name and xr[t] != round(base, 12)]
    assert len(moved) == 2                                       # its two steps
    # every shared column runs both records, each record's trigger point its own record alone
    shared = len(x) - len(p.parts)
    assert [name for name, _ in runs].count(p.parts[0].name) == 2 * shared + 2
    assert len(runs) == 2 * 2 * shared + 2 * len(p.parts)
    # and the column is the one fresh joint simulations give
    h = used[k]
    xp, xm = x.copy(), x.copy()
    xp[k] += h
    xm[k] -= h
    fresh = build_problem(records, "LW", Settings())
    assert np.array_equal(J[:, :, k], 0.5 * ((fresh.simulate(xp) - y0) / h + (y0 - fresh.simulate(xm)) / h))
    assert not np.any(J[:, :7, k])   # the first record does not see the second's trigger point
