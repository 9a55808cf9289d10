"""The Hunt-Crossley damping laws (issue 4), checked against the exact
restitution relation.

The predicted restitution of every law is obtained here by solving
ln((1+chi)/(1-e chi)) = (1+e) chi with scipy's brentq for the law's chi(e),
with chi(e) written out from the brief's table: nothing is taken from the
code under test or from a pasted table. The simulated restitution comes from
the C single-impact harness (chain solver, chain force, chain onset memory).
"""
from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from lss_fmu import contact_laws as cl

E_GRID = [round(0.2 + 0.1 * k, 1) for k in range(8)]          # 0.2 ... 0.9
LAW_CODES = {"HC": 1, "HW": 2, "LW": 3, "LN": 4, "GZ": 5, "FL": 6}


# --- the test's own reference ------------------------------------------------------

def relation(chi: float, e: float) -> float:
    """ln((1+chi)/(1-e chi)) - (1+e) chi, with log1p so that small chi keeps its digits."""
    return math.log1p(chi) - math.log1p(-e * chi) - (1.0 + e) * chi


def ref_restitution(chi: float) -> float:
    """The e in (0, min(1, 1/chi)) that an impact with damping factor chi has."""
    if chi == 0.0:
        return 1.0
    hi = min(1.0, 1.0 / chi) * (1.0 - 1e-13)
    if relation(chi, hi) <= 0.0:     # chi above ~30: the root is within 1e-13 of 1/chi
        return hi
    return brentq(lambda e: relation(chi, e), 0.0, hi, xtol=1e-15)


def ref_chi_exact(e: float) -> float:
    """The nonzero root chi in (0, 1/e) of the relation for a given e, for
    e in [0.05, 0.999] where plain double arithmetic brackets it cleanly (the
    root lies above LW's 3(1-e)/4, and below 1/e by more than 1e-13)."""
    assert 0.05 <= e <= 0.999
    lo = 0.9 * 0.75 * (1.0 - e)
    hi = (1.0 / e) * (1.0 - 1e-13)
    return brentq(lambda x: relation(x, e), lo, hi, xtol=1e-15, rtol=1e-15)


def ref_chi(law: str, e: float) -> float:
    return {
        "HC": lambda: 3 * (1 - e) / 2,
        "HW": lambda: 6 * (1 - e) / ((2 * e - 1) ** 2 + 3),
        "LW": lambda: 3 * (1 - e) / 4,
        "LN": lambda: 3 * (1 - e * e) / 4,
        "GZ": lambda: ref_chi_exact(e),
        "FL": lambda: 8 * (1 - e) / (5 * e),
    }[law]()


# --- chi(e) and the exact relation in C ---------------------------------------------

@pytest.mark.parametrize("law", list(LAW_CODES))
def test_c_chi_matches_the_table(law):
    es = np.linspace(0.05, 0.999, 50) if law == "GZ" else list(np.linspace(0.02, 1.0, 50)) + [1 - 1e-9]
    for e in es:
        want = ref_chi(law, e)
        got = cl.c_chi(LAW_CODES[law], e)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-15), (law, e)
        assert cl.chi(law, e) == pytest.approx(want, rel=1e-9, abs=1e-15), (law, e)


def test_c_chi_rejects_bad_input():
    for e in (0.0, -0.1, 1.0 + 1e-12, math.nan, math.inf):
        assert math.isnan(cl.c_chi(1, e)), e
        assert math.isnan(cl.c_chi_exact(e)), e
    for code in (0, 7, -1):
        assert math.isnan(cl.c_chi(code, 0.5)), code
    assert math.isnan(cl.c_restitution_of_chi(-1.0))
    assert math.isnan(cl.c_restitution_of_chi(math.nan))


def test_exact_chi_robust_from_small_e_to_one():
    """GZ's chi from e = 0.01 to 1 (chi -> 0): C against scipy, both limits,
    and the round trip through the inverse."""
    for e in np.concatenate([np.geomspace(0.05, 0.5, 15), 1 - np.geomspace(1e-3, 0.5, 15)]):
        assert cl.c_chi_exact(e) == pytest.approx(ref_chi_exact(e), rel=1e-10), e
    for e in np.concatenate([np.geomspace(0.01, 0.5, 25), 1 - np.geomspace(1e-10, 0.5, 25)]):
        chi_c = cl.c_chi_exact(e)
        assert 0 < chi_c < 1 / e
        assert cl.c_restitution_of_chi(chi_c) == pytest.approx(e, abs=1e-12), e
        assert cl.restitution_of_chi(cl.chi_exact(e)) == pytest.approx(e, abs=1e-12), e
    assert cl.c_chi_exact(1.0) == 0.0
    assert cl.c_restitution_of_chi(0.0) == 1.0
    # e -> 1: chi -> 3(1-e)/2 (Hunt-Crossley is the first-order limit)
    assert cl.c_chi_exact(1 - 1e-8) == pytest.approx(1.5e-8, rel=1e-6)
    # e -> 0: chi -> 1/e
    assert cl.c_chi_exact(0.01) == pytest.approx(100.0, rel=1e-12)


# --- the single-impact harness --------------------------------------------------------

def _grid_errors(tol: float, onset_rule: int = 0) -> dict:
    errs = {}
    for law in LAW_CODES:
        for n in (1.0, 1.5):
            for e in E_GRID:
                r = cl.simulate_impact(law, e, n=n, tol=tol, onset_rule=onset_rule)
                errs[law, n, e] = r.e_eff - ref_restitution(ref_chi(law, e))
    return errs


@pytest.mark.parametrize("law", list(LAW_CODES))
@pytest.mark.parametrize("n", [1.0, 1.5])
def test_simulated_restitution_matches_exact_relation(law, n):
    for e in E_GRID:
        r = cl.simulate_impact(law, e, n=n, K=2e7, m=3.0, v_i=0.4, v_min=1e-3, tol=1e-8)
        pred = ref_restitution(ref_chi(law, e))
        assert abs(r.e_eff - pred) < 1e-3, (law, n, e, r.e_eff, pred)
        assert abs(r.e_eff - pred) < 1e-4, (law, n, e, r.e_eff, pred)   # what it really achieves
        assert r.v_onset == pytest.approx(0.4, rel=1e-3)
        assert r.chi == pytest.approx(ref_chi(law, e), rel=1e-9)
        if law == "GZ":
            assert abs(r.e_eff - e) < 1e-3, (n, e, r.e_eff)


def test_error_falls_with_tolerance():
    worst = {tol: max(abs(v) for v in _grid_errors(tol).values()) for tol in (1e-5, 1e-7, 1e-9)}
    assert worst[1e-9] < worst[1e-7] < worst[1e-5] < 1e-3, worst
    assert worst[1e-9] < 1e-5, worst


def test_chain_error_settings_keep_restitution_within_1e3():
    """With the chain's error scales (1e-2 m, 1e-2 m/s + relative rate) and
    its default solver.tolerance 1e-4, at a steering-wheel-like contact."""
    worst = 0.0
    for law in LAW_CODES:
        for e in E_GRID:
            r = cl.simulate_impact(law, e, K=4e7, n=1.5, m=20.0, v_i=0.05, v_min=1e-3, tol=1e-4, h_max=0.01,
                                   scale_delta=1e-2, scale_rate=1e-2, rel_rate=1.0)
            worst = max(worst, abs(r.e_eff - ref_restitution(ref_chi(law, e))))
    assert worst < 1e-3, worst


@pytest.mark.parametrize("law,e", [("HC", 0.3), ("FL", 0.5), ("GZ", 0.7), ("LN", 0.9)])
def test_independent_of_mass_stiffness_and_speed(law, e):
    pred = ref_restitution(ref_chi(law, e))
    got = []
    for m in (1e-2, 1.0, 1e2):
        for K in (1e3, 1e6, 1e9):
            for v_i in (1e-2, 1.0, 1e2):
                r = cl.simulate_impact(law, e, K=K, n=1.5, m=m, v_i=v_i, v_min=1e-4, tol=1e-8)
                got.append(r.e_eff)
                # the rest scales as dimensional analysis says
                d_star = (2.5 * m * v_i ** 2 / (2 * K)) ** 0.4
                assert 0.3 < r.delta_max / d_star <= 1.0 + 1e-6
                assert 0.3 < r.F_max / (K * d_star ** 1.5) <= 1.0 + 1e-6
                assert 1.0 < r.duration / (d_star / v_i) < 10.0
    got = np.array(got)
    assert np.ptp(got) < 1e-5, (law, e, np.ptp(got))
    assert np.max(np.abs(got - pred)) < 1e-4


def test_elastic_impact_is_exact():
    """e = 1: no damping; linear spring: duration pi sqrt(m/K), peak force
    v sqrt(K m); Hertz n = 1.5: peak indentation (5 m v^2 / 4K)^(2/5)."""
    for law in LAW_CODES:
        r = cl.simulate_impact(law, 1.0, K=1e4, n=1.0, m=2.0, v_i=0.3, tol=1e-10)
        assert r.e_eff == pytest.approx(1.0, abs=1e-6)
        assert r.duration == pytest.approx(math.pi * math.sqrt(2.0 / 1e4), rel=1e-6)
        assert r.F_max == pytest.approx(0.3 * math.sqrt(1e4 * 2.0), rel=1e-6)
    r = cl.simulate_impact("GZ", 1.0, K=1e6, n=1.5, m=2.0, v_i=0.5, tol=1e-10)
    d = (5 * 2.0 * 0.25 / (4 * 1e6)) ** 0.4
    assert r.delta_max == pytest.approx(d, rel=1e-6)
    assert r.F_max == pytest.approx(1e6 * d ** 1.5, rel=1e-6)


def test_slow_impacts_use_the_floor_v_min():
    """Below v_min the contact remembers v_min: the law acts with
    chi * v_i / v_min, as the relation then predicts."""
    for law in ("HC", "GZ", "FL"):
        r = cl.simulate_impact(law, 0.5, v_i=0.01, v_min=0.05, K=1e6, n=1.5, tol=1e-8)
        assert r.v_onset == 0.05
        pred = ref_restitution(ref_chi(law, 0.5) * 0.01 / 0.05)
        assert abs(r.e_eff - pred) < 1e-4, (law, r.e_eff, pred)


def test_extreme_restitutions_run():
    """e from 0.01 (FL's chi = 158) to 1 for every law: the harness completes
    and still matches the relation."""
    for law in LAW_CODES:
        for e in (0.01, 0.05, 0.999, 1.0):
            r = cl.simulate_impact(law, e, n=1.0, tol=1e-8)
            pred = e if law == "GZ" else ref_restitution(ref_chi(law, e))
            assert abs(r.e_eff - pred) < 1e-4, (law, e, r.e_eff, pred)


def test_hermite_onset_alternative_is_at_least_as_accurate():
    lin = max(abs(v) for v in _grid_errors(1e-6, 0).values())
    her = max(abs(v) for v in _grid_errors(1e-6, 1).values())
    assert her <= lin * 1.05, (lin, her)


def test_harness_rejects_bad_input():
    bad = [dict(law=7), dict(e=0.0), dict(e=1.5), dict(e=math.nan), dict(K=0.0), dict(m=-1.0),
           dict(v_i=0.0), dict(v_min=0.0), dict(tol=0.0), dict(tol=math.nan), dict(n=0.0),
           dict(h_max=-1.0), dict(onset_rule=2)]
    for kw in bad:
        args = dict(law=1, e=0.5) | kw
        law, e = args.pop("law"), args.pop("e")
        with pytest.raises(ValueError):
            cl.simulate_impact(law, e, **args)


def test_trace_is_a_hysteresis_loop():
    r = cl.simulate_impact("HC", 0.5, n=1.5, tol=1e-8, trace=2000)
    t, d, v, F = r.trace.T
    assert np.all(np.diff(t) > 0) and np.all(F >= 0)
    inside = d > 0
    # loading (v > 0) carries more force than unloading (v < 0) at the same indentation
    dl, Fl = d[inside & (v > 0)], F[inside & (v > 0)]
    du, Fu = d[inside & (v < 0)], F[inside & (v < 0)]
    grid = np.linspace(0.2, 0.8, 7) * r.delta_max
    order_u = np.argsort(du)
    assert np.all(np.interp(grid, dl, Fl) > np.interp(grid, du[order_u], Fu[order_u]))


# --- the FMU rejects bad contact parameters -----------------------------------------

@pytest.fixture(scope="module")
def sim(fmu_file):
    """An instance of our own (in Instantiated state throughout), from the
    session's freshly built FMU (tests/conftest.py)."""
    from lss_fmu.runner import ChainSimulator
    with ChainSimulator(fmu_file) as s:
        yield s


BAD_VALUES = [
    *[(f"contact.{k}", v) for k in ("e_JA", "e_JR", "e_SW", "e_RW")
      for v in (0.0, -0.2, 1.0 + 1e-9, 1.5, math.nan, math.inf)],
    *[("contact.v_min", v) for v in (0.0, -1.0, math.nan)],
    *[("contact.model", v) for v in (0, 7, -1, 100)],
]


@pytest.mark.parametrize("name,value", BAD_VALUES)
def test_fmu_rejects_bad_contact_parameter(sim, name, value):
    from lss_fmu.runner import SimulationError
    before = sim.get(name)
    with pytest.raises(SimulationError) as info:
        sim.set(name, value)
    fmu_words = str(info.value).split(": ", 1)[1]   # after the runner's "cannot set ...: "
    assert name in fmu_words, fmu_words
    assert sim.get(name) == before          # the old value stands
    # the raw FMI call: fmi2Error (3) and a logged message naming the variable
    var = sim.variables[name]
    sim.messages.clear()
    vr = (ctypes.c_uint * 1)(var.valueReference)
    if var.type == "Real":
        status = sim.fmu.dll.fmi2SetReal(sim.fmu.component, vr, 1, (ctypes.c_double * 1)(value))
    else:
        status = sim.fmu.dll.fmi2SetInteger(sim.fmu.component, vr, 1, (ctypes.c_int * 1)(int(value)))
    assert status == 3
    assert any(s == 3 and name in msg for s, _, msg in sim.messages), sim.messages


@pytest.mark.parametrize("name,value", [("contact.e_JA", 1.0), ("contact.e_RW", 0.2), ("contact.e_SW", 1e-3),
                                        ("contact.v_min", 0.01), ("contact.model", 5), ("contact.model", 6)])
def test_fmu_accepts_good_contact_parameter(sim, name, value):
    sim.set(name, value)
    assert sim.get(name) == pytest.approx(value)
