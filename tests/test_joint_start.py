"""Where a joint identification starts (identification.pipeline.joint_start, issue 17):
the first record alone, then each further record's trigger point scanned on
its first window."""
from __future__ import annotations

import numpy as np
import pytest

from identification.pipeline import growing, rest_fit
from identification.objective.joint import JointProblem, own
from identification.pipeline.joint_start import single_start
from identification.pipeline.rest_fit import trigger_scan
from identification.objective.problem import from_measurement, weighted_residual
from identification.objective.uncertainty import intervals
from identification.pipeline.windowing import truncated
from lss_fmu.design import TRIGGER
from lss_fmu.measurement import load_measurement
from lss_fmu.rig import DEFAULT_SEED, folder_name, load_truth, run_measurement, true_design_values
from lss_fmu.runner import ChainSimulator

NUMBER, SECONDS, WINDOW = 2, 1.2, 0.6   # layout 1: a start-stop (its stop at 1 s), the first 0.6 s
LAYOUT5_NUMBER = 16   # a layout-5 sorter whose trigger points' valleys move with the pretension
LAYOUT2_NUMBER, LAYOUT2_SEED = 5, 11   # a layout-2 sorter (another rig seed) whose pretension is 7.7 % off nominal


@pytest.fixture(scope="module")
def two_records(tmp_path_factory, fmu_file):
    from lss_fmu import measurement as M
    from lss_fmu.rig import folder_name, run_measurement
    from lss_fmu.runner import ChainSimulator
    out = []
    for k in range(2):
        folder = tmp_path_factory.mktemp(f"joint_start_r{k}")
        with ChainSimulator() as s:
            run_measurement("recovery", NUMBER, folder, s, protocol="start-stop", lap_seconds=SECONDS, repeat=k)
        out.append(M.load_measurement(folder / folder_name(NUMBER)))
    return out


def _joint(records):
    parts = [from_measurement(r, "LW", window=WINDOW, tare=True, objective="likelihood") for r in records]
    truth = [true_design_values(load_truth(r)) for r in records]
    return JointProblem(parts), truth


def _in_the_starts_valley(jp, x, x_start):
    """A start at the truth is followed, not left: the end point fits at least
    as well, and e_JA, e_SW and e_RW are within 3 sd of the start by the
    record's own intervals there (on these 0.6 s windows one sd is 0.02-0.03:
    a fixed tolerance of 0.03 would test the noise draw; e_JR is not
    identifiable here)."""
    assert jp(x) <= jp(x_start) * (1 + 1e-3), (jp(x), jp(x_start))
    sd = {iv.name: iv.sd for iv in intervals(jp, x)}
    for c in ("e_JA", "e_SW", "e_RW"):
        k = jp.free.index(f"contact.{c}")
        assert abs(x[k] - x_start[k]) <= 3 * sd[f"contact.{c}"], (c, x[k], x_start[k], sd[f"contact.{c}"])


def test_the_trigger_scan_finds_a_records_trigger_point(two_records):
    jp, truth = _joint(two_records)
    part = jp.parts[1]
    w = 1.0 / np.asarray(part.noise, float) ** 2
    lo, hi = part.bounds[TRIGGER]
    s, S, used = trigger_scan(part, truth[0], w, 0.3)   # the shared values as they are, its own trigger not
    assert used == 52 and lo <= s <= hi
    assert abs(s - truth[1][TRIGGER]) < 0.01, (s, truth[1][TRIGGER])
    x_true = np.array([truth[1][n] for n in part.free])
    q = truncated(part, part.times[0] + 0.3)
    S_true = weighted_residual(q, q.simulate(x_true), w)[1] / q.samples.size
    assert S <= S_true * 1.02   # at least as good as the truth's trigger point, to the fine grid's step


def test_a_start_given_skips_the_complex(two_records, monkeypatch):
    jp, truth = _joint(two_records)
    x_true = np.array([{**truth[0], own(1): truth[1][TRIGGER]}[n] for n in jp.free])

    def no_complex(*a, **k):
        raise AssertionError("the complex ran although a start was given")
    monkeypatch.setattr(growing, "identify", no_complex)
    w = 1.0 / np.asarray(jp.noise, float) ** 2
    x, info = growing.grow(jp, start=x_true, channel_weights=w, reset_unseen=True)
    assert not info["unseen"]                                   # nothing reset: the start is not random
    assert all(t["S_per_sample"] < 1.3 for t in info["windows"])   # at the noise on every window
    _in_the_starts_valley(jp, x, x_true)                          # the CoRs stay where the truth put them


def test_the_single_start_is_the_first_record_and_the_others_triggers(two_records):
    jp, truth = _joint(two_records)
    w = 1.0 / np.asarray(jp.noise, float) ** 2
    x, info = single_start(jp, w, evals=40, first=0.3, seed=1, profile_points=0)
    vals = jp.values(x)
    assert [t["record"] for t in info["triggers"]] == [1]
    assert vals[own(1)] == info["triggers"][0]["trigger"]
    assert info["single"][-1]["window_s"] == pytest.approx(WINDOW, abs=0.01)
    assert info["nfev"] > 40 + 52
    # the scan with the first record's values, as found, puts the second record's trigger near its truth
    assert abs(vals[own(1)] - truth[1][TRIGGER]) < 0.05


class _Complex:
    """What identify returns, for a stand-in complex that stops at `x`."""

    def __init__(self, x):
        self.x, self.nfev = np.asarray(x, float), 1


def _joint_truth(records):
    jp, truth = _joint(records)
    return jp, np.array([{**truth[0], own(1): truth[1][TRIGGER]}[n] for n in jp.free])


def test_a_retry_is_not_asked_where_the_complex_reaches_the_noise(two_records, monkeypatch):
    jp, x_true = _joint_truth(two_records)
    monkeypatch.setattr(growing, "identify", lambda q, **k: _Complex(x_true))

    def no_retry():
        raise AssertionError("retried although the complex's first window is at the noise")
    w = 1.0 / np.asarray(jp.noise, float) ** 2
    x, info = growing.grow(jp, channel_weights=w, profile_points=0, retry=no_retry, first=0.3, growth=3.0)
    assert info["retry"] is None
    assert info["windows"][0]["S_per_sample"] < 1.2


def test_a_retry_replaces_a_complex_left_above_the_noise(two_records, monkeypatch):
    jp, x_true = _joint_truth(two_records)
    x_off = np.array(jp.x0_vector(), float)   # the start values: far above the noise on the first window
    monkeypatch.setattr(growing, "identify", lambda q, **k: _Complex(x_off))
    asked = []

    def retry():
        asked.append(1)
        return x_true, 7
    w = 1.0 / np.asarray(jp.noise, float) ** 2
    x, info = growing.grow(jp, channel_weights=w, profile_points=0, retry=retry, reset_unseen=True, first=0.3,
                           growth=3.0)
    assert asked == [1]
    r = info["retry"]
    assert r["taken"] and r["S_per_sample_retry"] < 1.2 < r["S_per_sample_complex"]
    assert info["unseen"] == []                      # nothing reset on the retry's point
    assert info["windows"][0]["S_per_sample"] == pytest.approx(r["S_per_sample_retry"])
    _in_the_starts_valley(jp, x, x_true)


def test_a_failed_retry_leaves_the_complexs_point(two_records, monkeypatch):
    jp, x_true = _joint_truth(two_records)
    x_off = np.array(jp.x0_vector(), float)
    monkeypatch.setattr(growing, "identify", lambda q, **k: _Complex(x_off))
    w = 1.0 / np.asarray(jp.noise, float) ** 2
    q = truncated(jp, jp.times[0] + 0.3)
    S_off = weighted_residual(q, q.simulate(x_off), w)[1] / q.samples.size

    def broken():
        raise RuntimeError("the first record's complex could not start")
    x, info = growing.grow(jp, channel_weights=w, profile_points=0, retry=broken, first=0.3, growth=3.0)
    r = info["retry"]
    assert not r["taken"] and r["S_per_sample_retry"] == np.inf
    assert r["S_per_sample_complex"] == pytest.approx(S_off)
    assert info["windows"][0]["S_per_sample"] == pytest.approx(S_off)   # the complex's point went on


def test_the_auto_start_takes_the_first_record_where_the_complex_fails(two_records, monkeypatch):
    from identification.pipeline import identify_grown as ig
    jp, x_true = _joint_truth(two_records)
    monkeypatch.setattr(growing, "identify", lambda q, **k: _Complex(jp.x0_vector()))
    single = {"single": [{"window_s": 0.6, "S_per_sample": 1.0}], "from_window_s": 0.6,
              "triggers": [{"record": 1, "trigger": float(x_true[jp.free.index(own(1))]), "S_per_sample": 1.0}],
              "nfev": 5}
    monkeypatch.setattr(ig, "single_start", lambda *a, **k: (x_true, single))
    monkeypatch.setattr(ig, "PROFILE_POINTS", 0)   # the stand-in complex's point left as it is
    res = ig.identify_grown(jp, start="auto", max_evals=5, refine_evals=0)
    assert "started from the first record alone" in res.message
    _in_the_starts_valley(jp, res.x, x_true)
    with pytest.raises(ValueError, match="start 'somewhere' is not one of complex, single, auto"):
        ig.identify_grown(jp, start="somewhere")


def test_restarts_take_the_next_seed_while_a_record_is_off_the_noise(two_records, monkeypatch):
    from types import SimpleNamespace

    from identification.pipeline import identify_grown as ig
    jp, x_true = _joint_truth(two_records)
    x_off = np.array(jp.x0_vector(), float)
    seeds = []

    def complex_by_seed(q, seed=0, **k):   # seed 0 stops off the truth, seed 1 on it
        seeds.append(seed)
        return _Complex(x_off if seed == 0 else x_true)
    monkeypatch.setattr(growing, "identify", complex_by_seed)
    monkeypatch.setattr(growing, "refine", lambda q, x, **k: SimpleNamespace(   # the windows move nothing
        x=np.asarray(x, float), f=float(q(np.asarray(x, float))), nfev=1, sim=q.simulate(np.asarray(x, float))))
    monkeypatch.setattr(ig, "PROFILE_POINTS", 0)
    res = ig.identify_grown(jp, start="complex", max_evals=5, refine_evals=0, restarts=2)
    assert seeds == [0, 1]                            # the second seed at the noise: no third
    k = [jp.free.index(f"contact.{c}") for c in ("e_JA", "e_SW", "e_RW")]
    assert np.allclose(res.x[k], x_true[k]) and res.restarts == 1
    assert "seed 1 kept" in res.message and "off the noise" in res.message
    seeds.clear()
    res = ig.identify_grown(jp, start="complex", max_evals=5, refine_evals=0, restarts=0)
    assert seeds == [0] and np.allclose(res.x[k], x_off[k])
    with pytest.raises(ValueError, match="restarts = -1 must be 0 or more"):
        ig.identify_grown(jp, restarts=-1)


def test_what_sets_the_chain_at_rest_is_the_pretension_and_the_trigger_points(two_records):
    from types import SimpleNamespace
    from lss_fmu.protocol import Protocol
    jp, _ = _joint(two_records)
    assert growing.at_rest(jp) == ["chain.pretension", TRIGGER, own(1)]
    steady = SimpleNamespace(protocol=Protocol("steady"), free=jp.free)
    assert growing.at_rest(steady) == []   # no start from rest: nothing relaxes


def test_holding_the_rest_relaxes_each_record_once_in_the_complex(two_records, monkeypatch):
    """hold_rest: the complex varies what does not move the chain at rest, so
    its evaluations restore the records' relaxed chains instead of relaxing
    anew; Levenberg-Marquardt then frees the pretension and the trigger points
    on the first window."""
    from lss_fmu.runner import ChainSimulator
    jp, _ = _joint(two_records)
    q = truncated(jp, jp.times[0] + 0.3)   # the first window only: no growing windows after it
    w = 1.0 / np.asarray(q.noise, float) ** 2
    seen, relaxed = {}, []
    keep = ChainSimulator._keep_rest

    def counted(self, key):
        relaxed.append(seen.get("in_complex", False))
        return keep(self, key)
    monkeypatch.setattr(ChainSimulator, "_keep_rest", counted)
    real = growing.identify

    def spy(problem, **kw):
        seen["free"], seen["in_complex"] = tuple(problem.free), True
        try:
            return real(problem, **kw)
        finally:
            seen["in_complex"] = False
    monkeypatch.setattr(growing, "identify", spy)
    x, info = growing.grow(q, evals=15, channel_weights=w, profile_points=1, hold_rest=True)
    assert info["rest_held"] == ["chain.pretension", TRIGGER, own(1)]
    assert not set(info["rest_held"]) & set(seen["free"])
    assert sum(relaxed_in for relaxed_in in relaxed) <= len(q.parts)   # once per record, or restored
    assert len(x) == len(q.free)
    start = dict(zip(q.free, q.x0_vector()))
    assert any(abs(v - start[n]) > 0 for n, v in zip(q.free, x) if n in info["rest_held"])   # freed and moved
    # without the hold, every evaluation of the complex moves the pretension and relaxes again
    relaxed.clear()
    growing.grow(q, evals=15, channel_weights=w, profile_points=1)
    assert sum(relaxed) > 2 * len(q.parts)


def test_the_rest_fit_finds_the_pretension_and_each_trigger_point_from_another_valley(two_records):
    """fit_rest from start values a valley or more away (each trigger point
    0.45 m off the truth on either side or at its bound, the pretension at
    its bounds' middle) with the CoRs at their start values: the pretension
    within 3 %, each record's trigger point within 3 cm. S repeats itself
    every few decimetres along the trigger point: from the first record's
    start, Levenberg-Marquardt alone stays at the bound, 0.43 m off."""
    from identification.pipeline.rest_fit import REST_COARSE, fit_rest
    jp, truth = _joint(two_records)
    q = truncated(jp, jp.times[0] + 0.3)
    w = 1.0 / np.asarray(q.noise, float) ** 2
    start = dict(q.x0)
    for k, sign in ((0, 1.0), (1, -1.0)):
        lo, hi = q.parts[k].bounds[TRIGGER]
        start[own(k)] = float(np.clip(truth[k][TRIGGER] + sign * 0.45, lo, hi))
    q = JointProblem(q.parts, free=list(q.free), x0=start)
    rest = growing.at_rest(q)
    vals, used = fit_rest(q, rest, w, 79)
    assert set(vals) == set(rest) and used >= 2 * REST_COARSE
    p_true = truth[0]["chain.pretension"]
    assert abs(vals["chain.pretension"] - p_true) < 0.03 * p_true, (vals["chain.pretension"], p_true)
    for k in (0, 1):
        assert abs(vals[own(k)] - truth[k][TRIGGER]) < 0.03, (k, vals[own(k)], truth[k][TRIGGER])


def _records(tmp_path_factory, number: int, seed: int, tag: str) -> list:
    out = []
    for k in range(2):
        folder = tmp_path_factory.mktemp(f"{tag}_r{k}")
        with ChainSimulator() as s:
            run_measurement("recovery", number, folder, s, seed=seed, protocol="start-stop", lap_seconds=SECONDS,
                            repeat=k)
        out.append(load_measurement(folder / folder_name(number)))
    return out


@pytest.fixture(scope="module")
def layout5_records(tmp_path_factory, fmu_file):
    return _records(tmp_path_factory, LAYOUT5_NUMBER, DEFAULT_SEED, "rest_fit_l5")


@pytest.fixture(scope="module")
def layout2_records(tmp_path_factory, fmu_file):
    return _records(tmp_path_factory, LAYOUT2_NUMBER, LAYOUT2_SEED, "rest_fit_l2")


def _rest_fit_errors(jp, truth, pretension: float, monkeypatch, **patches) -> tuple:
    """(pretension's relative error, largest trigger point error in m,
    simulations) of fit_rest on jp's first 0.3 s from `pretension` (the
    trigger points at their marks, the CoRs at their start values), with
    rest_fit's names in `patches` replaced."""
    for name, value in patches.items():
        monkeypatch.setattr(rest_fit, name, value)
    q = truncated(jp, jp.times[0] + 0.3)
    w = 1.0 / np.asarray(q.noise, float) ** 2
    q = JointProblem(q.parts, free=list(q.free), x0={**q.x0, "chain.pretension": pretension})
    vals, used = rest_fit.fit_rest(q, growing.at_rest(q), w, 79)
    p_true = truth[0]["chain.pretension"]
    off = max(abs(vals[own(k)] - truth[k][TRIGGER]) for k in range(len(jp.parts)))
    return vals["chain.pretension"] / p_true - 1.0, off, used


def test_the_rest_fit_scans_the_pretension_over_its_bounds(layout2_records, monkeypatch):
    """A layout-2 sorter whose pretension lies 7 % above its nominal value,
    the rest fit started from the nominal: S along the pretension is rough
    on a scale of 1 %, and Levenberg-Marquardt from there stops short of
    the truth, where the trigger points' deepest valleys lie a valley or more off
    (and a second scan at that pretension finds the same ones). The scan
    over the bounds first: the pretension within 1 %, each trigger point
    within 3 cm. Without the scan the same start ends a valley off."""
    jp, truth = _joint(layout2_records)
    nominal = jp.x0["chain.pretension"]
    assert truth[0]["chain.pretension"] / nominal - 1 > 0.05   # the case this test is about
    rel, off, used = _rest_fit_errors(jp, truth, nominal, monkeypatch)
    assert abs(rel) < 0.01 and off < 0.03, (rel, off)
    rel0, off0, _ = _rest_fit_errors(jp, truth, nominal, monkeypatch, _scan_shared=lambda *a: 0)
    assert off0 > 0.1, (rel0, off0)
    assert used >= rest_fit.SHARED_COARSE


def test_the_rest_fit_scans_again_at_the_pretension_it_found(layout5_records, monkeypatch):
    """The pretension started 4.8 % above the truth on a layout-5 start-stop,
    and left there by the pretension's own fit (no scan of it): the first
    record's deepest trigger valley lies a quarter metre off its trigger
    point at that pretension; the joint fit then finds the pretension but
    keeps the valley, off the noise (with one round of scans the first
    record ends 0.26 m off). With the scans repeated at the fitted
    pretension both trigger points come within 3 cm and the pretension
    within 0.5 %, and a trigger point was scanned more than once."""
    jp, truth = _joint(layout5_records)
    scans = []
    real_scan = rest_fit.trigger_scan

    def counted(*args, **kwargs):
        scans.append(1)
        return real_scan(*args, **kwargs)
    start = 1.048 * truth[0]["chain.pretension"]
    rel, off, used = _rest_fit_errors(jp, truth, start, monkeypatch, _scan_shared=lambda *a: 0,
                                      trigger_scan=counted)
    assert abs(rel) < 0.005 and off < 0.03, (rel, off)
    assert len(scans) > len(jp.parts), scans   # the second round ran
