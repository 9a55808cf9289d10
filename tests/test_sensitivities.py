"""Forward sensitivities from the core (issue 50): follower chains on the
leading chain's own steps give the derivatives of the force channels by a
parameter from one run (fmu_src/sensitivity.c), and the identification's
Jacobians take them (identification.objective.jacobian.exact_columns).

Checked against central differences of whole runs, against themselves at
other steps (the derivative of the discrete solution does not depend on the
step), for the nominal channels untouched, through FMU states, and with the
bad set-ups a master can make."""
from __future__ import annotations

import numpy as np
import pytest

from identification.objective.jacobian import jacobian
from identification.objective.joint import JointProblem, own
from identification.objective.parallel import pooled
from identification.objective.problem import from_measurement
from identification.pipeline.driver import build_problem
from identification.pipeline.settings import Settings, settings_from
from lss_fmu.design import TRIGGER
from lss_fmu.rig import load_truth, true_design_values
from lss_fmu.runner import ChainSimulator, SimulationError
from lss_fmu.variables import FORCE_CHANNELS, sensitivity_output, value_reference

H = 1.0 / 600
BASE = {"layout.name": "layout7", "contact.model": 2, "chain.v_init": 0.0, "chain.transducer": 0,
        "drive.v_ref": 0.0, "chain.s_start": 3.0, "chain.relax_time": 1.0,
        "contact.e_SW": 0.5, "contact.e_JA": 0.4, "chain.pretension": 0.004, "drive.Kp": 2000.0}


def speed(t: float) -> float:
    return 0.0 if t < 0.05 else min(1.5, 3.0 * (t - 0.05))


def with_sens(params: dict, steps: dict) -> tuple:
    """params asking for the sensitivities by `steps` (name -> step), and the channels to read."""
    p = dict(params, **{"sensitivity.n": len(steps)})
    channels = list(FORCE_CHANNELS)
    for k, (name, h) in enumerate(steps.items(), 1):
        p[f"sensitivity.p{k}.vr"] = value_reference(name)
        p[f"sensitivity.p{k}.step"] = h
        channels += [sensitivity_output(k, c) for c in FORCE_CHANNELS]
    return p, channels


def run(params: dict, channels, T: float = 0.5, tol: float = 1e-6) -> np.ndarray:
    rows = []
    with ChainSimulator() as sim:
        for t, v in sim.stream(H, channels, params, tol, inputs={"drive.v_ref": speed}):
            rows.append(v.copy())
            if t >= T - 1e-12:
                break
    return np.array(rows)


@pytest.fixture(scope="module")
def followed():
    """One run from rest with four sensitivities, the steps tiny."""
    steps = {"contact.e_SW": 1e-6, "chain.pretension": 1e-9, "chain.s_start": 1e-6, "drive.Kp": 1e-3}
    p, ch = with_sens(BASE, steps)
    return steps, run(p, ch)


def test_the_leader_is_the_run_without_followers(followed):
    _, Y = followed
    assert np.array_equal(Y[:, :7], run(BASE, FORCE_CHANNELS))


def test_each_column_is_the_central_difference_of_whole_runs(followed):
    """Within 3 % of central differences at steps small enough for the most
    nonlinear response (the pretension's) and large enough to stand above the
    step-size control's noise at 1e-6."""
    steps, Y = followed
    central = {"contact.e_SW": 1e-3, "chain.pretension": 3e-7, "chain.s_start": 1e-4, "drive.Kp": 5.0}
    for k, name in enumerate(steps):
        S = Y[:, 7 * (k + 1):7 * (k + 2)]
        up, down = dict(BASE), dict(BASE)
        up[name] += central[name]
        down[name] -= central[name]
        D = (run(up, FORCE_CHANNELS) - run(down, FORCE_CHANNELS)) / (2 * central[name])
        assert np.linalg.norm(S) > 0, name
        assert np.linalg.norm(S - D) <= 0.03 * np.linalg.norm(D), name


def test_the_derivative_does_not_depend_on_the_step(followed):
    """The followers differentiate the leader's discrete solution: a step ten
    times smaller gives the same columns (to 1 %), where the difference of
    two independent runs at that step is the solver's noise."""
    steps, Y = followed
    small = {n: h / 10 for n, h in steps.items()}
    p, ch = with_sens(BASE, small)
    Z = run(p, ch)
    assert np.linalg.norm(Z[:, 7:] - Y[:, 7:]) <= 0.01 * np.linalg.norm(Y[:, 7:])
    name, h = "contact.e_SW", steps["contact.e_SW"]
    moved = dict(BASE, **{name: BASE[name] + h})
    noisy = (run(moved, FORCE_CHANNELS, tol=1e-5) - run(BASE, FORCE_CHANNELS, tol=1e-5)) / h
    S = Y[:, 7:14]
    assert np.linalg.norm(noisy - S) > 0.5 * np.linalg.norm(S)


def test_the_rest_state_moves_with_the_pretension_not_with_the_cors(followed):
    """The relaxation at rest overrides the CoRs and the gains (chain_relax_ignores):
    their followers start where the leader does, the pretension's and the
    trigger point's do not."""
    steps, Y = followed
    first = {name: Y[0, 7 * (k + 1):7 * (k + 2)] for k, name in enumerate(steps)}
    assert not np.any(first["contact.e_SW"]) and not np.any(first["drive.Kp"])
    assert np.abs(first["chain.pretension"][0]) > 1e3 and np.any(first["chain.s_start"])


def test_an_fmu_state_keeps_the_followers():
    """Restored, the leader and its followers go on as they would have, bit for bit."""
    p, ch = with_sens(BASE, {"contact.e_JA": 1e-6, "chain.pretension": 1e-9})
    with ChainSimulator() as sim:
        it = sim.stream(H, ch, p, 1e-6, inputs={"drive.v_ref": speed})
        for k, (t, _) in enumerate(it):
            if t >= 0.1 - 1e-12:
                break
        state = sim.fmu.getFMUstate()
        first = np.array([next(it)[1].copy() for _ in range(30)])
        sim.fmu.setFMUstate(state)
        again = []
        for i in range(k, k + 30):      # the stream's own times: t = i * H
            sim.set("drive.v_ref", speed(i * H))
            sim.fmu.doStep(i * H, (i + 1) * H - i * H)
            again.append(np.array(sim.fmu.getReal([sim.vr(c) for c in ch])))
        sim.fmu.freeFMUstate(state)
    assert np.array_equal(first, np.array(again))
    assert np.all(np.any(first[:, 7:], axis=0)[[0, 7]])


@pytest.mark.parametrize("bad, match", [
    ({"sensitivity.p1.vr": value_reference("drive.v_ref")}, r"sensitivity.p1.vr = \d+: not a Real parameter"),
    ({"sensitivity.p1.vr": 0}, r"sensitivity.p1.vr = 0: not a value reference"),
    ({"sensitivity.p1.vr": value_reference("solver.h_max")}, "a setting of the run"),
    ({"sensitivity.p1.step": 0.0}, r"sensitivity.p1.step = 0 must be finite and not 0"),
    ({"sensitivity.p1.step": 0.6}, r"moves contact.e_SW from 0.5 to 1.1\d*, outside its range"),
    ({"sensitivity.n": 2, "sensitivity.p2.vr": value_reference("contact.e_SW"), "sensitivity.p2.step": 1e-6},
     r"sensitivity.p2.vr = \d+ \(contact.e_SW\) repeats sensitivity.p1.vr"),
])
def test_a_set_up_the_followers_cannot_take_is_refused_by_name(bad, match):
    p, _ = with_sens(BASE, {"contact.e_SW": 1e-6})
    p.update(bad)
    with ChainSimulator() as sim:
        with pytest.raises(SimulationError, match=match):
            sim.start(p, 1e-5)


def test_a_tunable_that_moves_a_follower_out_of_range_is_refused_in_step_mode():
    p, _ = with_sens(BASE, {"contact.e_SW": 1e-3})
    with ChainSimulator() as sim:
        sim.start(p, 1e-5)
        sim.step(H)
        with pytest.raises(SimulationError, match=r"sensitivity.p1.step = 0.001 moves contact.e_SW"):
            sim.set("contact.e_SW", 1.0)
        sim.set("contact.e_SW", 0.6)       # inside with its follower: taken
        sim.step(H)


@pytest.fixture(scope="module")
def records(rig_record):
    return [rig_record(20, "start-stop", 1.4, repeat=k) for k in range(2)]


def _problem(rec):
    p = from_measurement(rec, "HW", window=1.2, tare=True, objective="likelihood")
    p.sensitivities = True
    truth = true_design_values(load_truth(rec))
    lo, hi = np.array(p.bounds_array, float).T
    x = np.array([truth.get(n, 0.5 * (a + b)) for n, a, b in zip(p.free, lo, hi)])
    return p, np.clip(x + 0.03 * (hi - lo) * np.sin(np.arange(len(x))), lo, hi)


def test_a_record_from_rest_takes_every_design_column_but_the_set_point_from_the_core(records):
    p, x = _problem(records[0])
    assert [p.free[k] for k in p.exact_indices()] == [n for n in p.free if n != "drive.v_ref"]
    y, cols = p.simulate_exact(x, p.exact_indices())
    assert np.array_equal(y, p.simulate(x))
    w = 1.0 / p.noise ** 2
    Jd, _, rough = jacobian(p, x, y, weights=w, exact=False)
    Je, used, rough_e = jacobian(p, x, y, weights=w)
    for k, name in enumerate(p.free):
        diff = np.sqrt(np.sum((Je[:, :, k] - Jd[:, :, k]) ** 2 * w))
        size = np.sqrt(np.sum(Jd[:, :, k] ** 2 * w))
        # the differenced column is itself uncertain by its roughness (forward against backward)
        assert diff <= max(2.0 * rough[k], 0.05) * size, (name, diff / size, rough[k])
        assert used[k] > 0 and (rough_e[k] == 0.0) == (k in p.exact_indices())
    steady = from_measurement(records[0], "HW", window=1.2)
    assert steady.exact_indices() == ()       # not asked for: the default
    steady.sensitivities = True
    steady.protocol = type(p.protocol)()      # a record whose trigger is found while the chain runs
    assert steady.exact_indices() == ()


def test_a_joint_problem_gives_each_record_its_own_trigger_column(records):
    parts = [_problem(r)[0] for r in records]
    jp = JointProblem(parts)
    x = jp.x0_vector()
    ks = jp.exact_indices()
    assert jp.free.index(own(1)) in ks and jp.free.index(TRIGGER) in ks
    y, cols = jp.simulate_exact(x, ks)
    assert np.array_equal(y, jp.simulate(x))
    k0, k1 = jp.free.index(TRIGGER), jp.free.index(own(1))
    assert not np.any(cols[k1][:, :7]) and np.any(cols[k1][:, 7:])
    assert not np.any(cols[k0][:, 7:]) and np.any(cols[k0][:, :7])
    e = jp.free.index("contact.e_SW")
    solo, c = parts[1].simulate_exact(jp.part_x(1, x), [parts[1].free.index("contact.e_SW")])
    assert np.array_equal(cols[e][:, 7:], c[parts[1].free.index("contact.e_SW")])
    # the records side by side on two processes: the same arrays, bit for bit
    fresh = JointProblem([_problem(r)[0] for r in records])
    with pooled(fresh, workers=2):
        y2, cols2 = fresh.simulate_exact(x, ks)
    assert np.array_equal(y2, y) and all(np.array_equal(cols2[k], cols[k]) for k in ks)


def test_the_settings_switch_reaches_every_record(records):
    """Off by default (docs/benchmarks.md: it changes Levenberg-Marquardt's path); `sensitivities = true`
    in [identify] turns it on for every record of a joint problem."""
    on = build_problem(records, "HW", settings_from({"sensitivities": True}))
    off = build_problem(records, "HW", Settings())
    assert on.exact_indices() and off.exact_indices() == ()
    assert all(p.sensitivities for p in on.parts)


def test_a_carried_exact_step_is_not_differenced_with_when_the_core_fails(records, monkeypatch):
    """The steps an exact Jacobian reports for its core columns are the
    followers' (1e-6 of the range); carried into a Jacobian whose core run
    failed, those columns are differenced at the default step instead."""
    from identification.objective import jacobian as jac
    p, x = _problem(records[0])
    y = p.simulate(x)
    w = 1.0 / p.noise ** 2
    _, used, _ = jacobian(p, x, y, weights=w)
    span = np.array([b - a for a, b in p.bounds_array])
    ks = list(p.exact_indices())
    assert np.allclose(used[ks], jac.EXACT_STEP * span[ks])
    monkeypatch.setattr(jac, "exact_columns", lambda problem, x: {})   # the core's run failed
    _, again, rough = jacobian(p, x, y, weights=w, steps=used)
    assert np.all(again[ks] >= 0.5 * jac.REL_STEP * span[ks]), again[ks] / span[ks]
    assert np.all(np.isfinite(rough[ks]))
