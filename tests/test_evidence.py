"""The statistics behind a close-loop verdict (identification.loop.evidence, .noise,
.holdout and .departures; issue 18).

Pure numpy: white and correlated residuals made here, no FMU. What must hold:
the noise estimate finds the white noise under a smooth model error; the
likelihood-ratio test keeps its level on white noise and on a residual with
structure (the trap of issue 18: a flexible candidate fitting part of a
model error), and finds a real signature; the disturbances outside the
catalogue are told apart.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from identification.loop import departures as D
from identification.loop import evidence as E
from identification.loop import holdout as HO
from identification.objective import noise as NZ

N, K = 300, 7
T = np.arange(N) / 300.0
SIG = np.array([4.0, 3.0, 3.0, 2.0, 2.0, 2.0, 2.0])
W = 1.0 / SIG ** 2


def _col(j, y):
    g = np.zeros((N, K))
    g[:, j] = y
    return g


def _smooth(rng, scale=1.0):
    """A model error smooth over ~20 samples on every channel."""
    from scipy.ndimage import gaussian_filter1d
    e = gaussian_filter1d(rng.normal(size=(N, K)), 8.0, axis=0)
    return scale * e / e.std(axis=0) * SIG


def test_noise_estimate_sees_through_a_smooth_model_error():
    rng = np.random.default_rng(1)
    r = rng.normal(size=(N, K)) * SIG + _smooth(rng, 10.0)
    est = NZ.estimate_noise(r)
    assert np.all(np.abs(est / SIG - 1) < 0.25), est / SIG
    nz = NZ.noise_levels(r, {"transducer.joint.F_x": 1.0})   # incomplete declaration: estimated
    assert nz.source == "estimated"
    from lss_fmu.sensor import NOISE_STD
    assert NZ.noise_levels(r, NOISE_STD).source == "declared"


def _lr(r, cols, m=1, q=None):
    _, fit, S0, S1 = E.fit_gain(r, cols, W)
    return E.lr_test(S0, S1, cols, r - fit, W, q=q or len(cols), m=m)


def test_lr_test_keeps_its_level_on_white_noise():
    rng = np.random.default_rng(2)
    ps = []
    for k in range(300):
        r = rng.normal(size=(N, K)) * SIG
        cols = [_col(int(rng.integers(K)), np.sin(2 * np.pi * rng.uniform(2, 20) * T + rng.uniform(0, 6))),
                _col(int(rng.integers(K)), rng.normal(size=N).cumsum())]
        ps.append(_lr(r, cols).p)
    ps = np.array(ps)
    assert np.mean(ps < 0.05) <= 0.08 and np.mean(ps < 0.01) <= 0.025


def test_lr_test_is_not_fooled_by_a_structured_residual():
    """A smooth model error 3 sigma strong: a smooth unrelated signature fits a
    part of it; the white-noise chi^2 would call that significant, the test
    with the correlated residual's scale does not (at the level the loop uses)."""
    rng = np.random.default_rng(3)
    naive, ours = 0, 0
    for k in range(60):
        r = rng.normal(size=(N, K)) * SIG + _smooth(rng, 3.0)
        j = int(rng.integers(K))
        cols = [_col(j, np.cos(2 * np.pi * rng.uniform(1, 6) * T)), _col(j, np.sin(2 * np.pi * rng.uniform(1, 6) * T))]
        _, fit, S0, S1 = E.fit_gain(r, cols, W)
        from scipy import stats
        naive += stats.chi2.sf(S0 - S1, 2) < 1e-3
        ours += _lr(r, cols).p < 1e-3
    assert naive >= 20          # the trap
    assert ours <= 2


def test_lr_test_finds_a_real_signature():
    rng = np.random.default_rng(4)
    g = _col(2, np.sin(2 * np.pi * 7 * T))
    r = rng.normal(size=(N, K)) * SIG + 1.5 * g   # 1.5 N on a 3 N channel
    t = _lr(r, [g], m=100)
    assert t.significant and t.dbic > 0 and t.scale < 1.5


def test_folds_interleave_equal_blocks():
    f = HO.folds(300, 16)
    assert set(f) == {0, 1} and abs(f.sum() - 150) <= 10
    assert np.all(np.diff(np.nonzero(np.diff(f))[0]) >= 17)


class _Problem:
    """What departures() needs of a problem when the clock is not tried."""
    def __init__(self, samples):
        self.samples, self.times, self.tare = samples, T, None


@pytest.mark.parametrize("kind", ["crosstalk", "interference", "pulse"])
def test_departures_tell_the_disturbances_apart(kind):
    rng = np.random.default_rng(5)
    levels = np.column_stack([900 + 400 * np.sin(2 * np.pi * 1.3 * T + j) + 50 * np.sin(2 * np.pi * 9 * T * (j + 1))
                              for j in range(K)])
    noise = rng.normal(size=(N, K)) * SIG
    r = noise.copy()
    if kind == "crosstalk":
        r[:, 4] += 0.03 * (levels[:, 1] - levels[:, 1].mean())
    elif kind == "interference":
        r[:, 2] += 6.0 * np.sin(2 * np.pi * 71.3 * T + 0.4)
    else:
        u = (T - 0.41) / 0.1
        r[:, 5] += -40.0 * np.where(np.abs(u) < 0.5, 0.5 * (1 + np.cos(2 * np.pi * u)), 0.0)
    deps = D.departures(_Problem(levels + r), None, levels, r, [], W, excluded_hz=[(0.0, 40.0)], clock=False)
    best = max(deps, key=lambda d: d.test.dbic)
    assert best.family == kind and best.test.significant and best.test.dbic > 0, [(d.label, d.test.dbic) for d in deps]
    if kind == "interference":
        assert abs(best.detail["frequency_hz"] - 71.3) < 0.5 and best.detail["channel"].endswith("F_z")
    if kind == "crosstalk":
        assert best.detail["from"].endswith("F_y") and best.detail["into"].endswith("steering.F_right")
    if kind == "pulse":
        assert abs(best.detail["t"] - 0.41) < 0.05
    # none of them on white noise
    deps0 = D.departures(_Problem(levels + noise), None, levels, noise, [], W, excluded_hz=[(0.0, 40.0)], clock=False)
    assert not any(d.test.significant and d.test.dbic > 0 for d in deps0)


def test_excess_tells_noise_from_structure():
    rng = np.random.default_rng(6)
    white = rng.normal(size=(N, K)) * SIG
    assert not NZ.excess(white, SIG).any
    e = NZ.excess(white + _smooth(rng, 2.0) * (np.arange(K) == 3), SIG)
    assert list(np.nonzero(e.above)[0]) == [3]


def test_a_departure_beyond_the_candidate():
    """departures.beyond: crosstalk of channel 1 into channel 4 left in the
    extended residual stays significant; once the candidate's own columns can
    do the same (a gain on channel 4 of a signal correlated with channel 1),
    it no longer counts; a clock fit on the bound of its search never counts."""
    rng = np.random.default_rng(5)
    src = 300.0 * np.sin(2 * np.pi * 3.0 * T) + 40.0 * rng.standard_normal(N)
    dep_col = _col(4, src - src.mean())
    noise = rng.standard_normal((N, K)) * SIG
    r_ext = noise + 0.03 * dep_col
    lr0 = E.lr_test(1.0, 1.0, [dep_col], noise, W, 1, 42, 42)
    dep = D.Departure("crosstalk", "1 into 4", dataclasses.replace(lr0, p_adj=0.0, dbic=50.0), {}, [dep_col])
    t = D.beyond(dep, r_ext, W)
    assert t.significant and t.dbic > 0, t
    assert not D.beyond(dep, noise, W).significant
    similar = _col(4, 300.0 * np.sin(2 * np.pi * 3.0 * T + 0.05))   # the candidate's gain column
    t2 = D.beyond(dep, r_ext, W, J=[similar])
    assert t2.dS < 0.2 * t.dS, (t.dS, t2.dS)
    assert dep.counts
    clock = D.Departure("clock", "at the bound", dep.test, {"eps": D.CLOCK_MAX, "at_bound": True}, [dep_col])
    assert not clock.counts


def test_a_candidate_beyond_the_departure():
    """departures.candidate_beyond, the other way round: an effect in every
    channel that a crosstalk column imitates on one channel stays significant
    once the crosstalk has taken its share; a candidate that only imitates a
    real crosstalk does not."""
    rng = np.random.default_rng(7)
    src = 300.0 * np.sin(2 * np.pi * 3.0 * T) + 40.0 * rng.standard_normal(N)
    dep_col = _col(4, src - src.mean())
    eff = np.column_stack([np.sin(2 * np.pi * 3.0 * T + 0.3 * j) for j in range(K)]) * SIG * 3.0
    noise = rng.standard_normal((N, K)) * SIG

    def dep_on(r):
        _, _, S0, S1 = E.fit_gain(r, [dep_col], W)
        lr = E.lr_test(S0, S1, [dep_col], r, W, 1, 42, 42)   # taken as counting, whatever its own test
        return D.Departure("crosstalk", "1 into 4", dataclasses.replace(lr, p_adj=0.0, dbic=50.0), {}, [dep_col])

    def cand_on(r):   # the candidate's extension: its column fitted, the residual and S
        _, fit, S0, S1 = E.fit_gain(r, [eff], W)
        return r - fit, S0

    # the effect is there: its extension leaves the noise
    r_b = noise + eff
    dep = dep_on(r_b)
    assert dep.test.dS > 20.0   # the crosstalk alone explains a part
    r_e, S_b = cand_on(r_b)
    t = D.candidate_beyond(dep, S_b, r_e, [eff], W, 1, 20, 1)
    assert t.significant and t.dbic > 0, t
    # the crosstalk is there: the candidate's column takes a share of it, nothing beyond
    r_b = noise + 0.05 * dep_col
    dep = dep_on(r_b)
    r_e, S_b = cand_on(r_b)
    assert S_b - float(np.sum(r_e ** 2 * W)) > 20.0   # the candidate alone would explain a part
    t = D.candidate_beyond(dep, S_b, r_e, [eff], W, 1, 20, 1)
    assert not (t.significant and t.dbic > 0), t
    assert D.candidate_beyond(D.Departure("pulse", "-", dep.test, {}, None), S_b, r_e, [eff], W, 1, 20, 1) is None


class _Model:
    """A stand-in problem: the measured samples and a model run (simulate) of them."""

    def __init__(self, samples, run):
        self.samples, self.tare, self._run = samples, None, run

    def simulate(self, x):
        return self._run


def test_an_effect_must_matter_at_its_estimate():
    """candidates.switched_off: the extension's point with the effect off,
    against the extension. A fit whose fall came from the base parameters
    (the effect at a negligible amplitude) does not count; one whose effect
    carries the fall does."""
    from identification.loop.candidates import switched_off
    rng = np.random.default_rng(11)
    g = _col(2, 10.0 * np.sin(2 * np.pi * 7.0 * T))
    base_run = np.zeros((N, K))
    noise = rng.standard_normal((N, K)) * SIG
    kw = dict(q=1, m=10, m_effect=1, J=())
    # the record holds the effect: the extension's run has it, the base's does not
    samples = base_run + 3.0 * g + noise
    ext_run = base_run + 3.0 * g
    S_e = float(np.sum((samples - ext_run) ** 2 * W))
    on = switched_off(_Model(samples, base_run), None, _Model(samples, ext_run), ext_run, S_e, [g], W, kw)
    assert on["matters"] and on["dS"] > 100 and on["p_adj"] < 1e-6, on
    # the effect at 1e-9 of that: switched off, nothing changes
    ext_run = base_run + 3e-9 * g
    S_e = float(np.sum((samples - ext_run) ** 2 * W))
    off = switched_off(_Model(samples, base_run), None, _Model(samples, ext_run), ext_run, S_e, [g], W, kw)
    assert not off["matters"] and off["dS"] < 1e-3, off


def _round(number, outcome, *, confirmed=False, provisional=False):
    from identification.loop.attribution import Attribution
    from identification.loop.loop_result import Round
    r = Round(number, 1.0, np.ones(7), Attribution(1.0, 1.0, [], []), f"round {number}: {outcome}",
              effect=f"effect{number}", confirmed=confirmed, provisional=provisional, outcome=outcome)
    r.verdict_if_confirmed = f"effect{number} confirmed"
    return r


def test_a_provisional_effect_needs_a_later_model_at_the_noise():
    """An effect that passes the tests while the model with it stays above the
    noise is confirmed only when a later round's model, carrying it, reaches
    the noise (close_loop.settle_provisional)."""
    from identification.loop.close_loop import settle_provisional
    # alone (one round, or nothing found after it): not confirmed
    one = [_round(1, "not in the catalogue", provisional=True)]
    settle_provisional(one)
    assert not one[0].confirmed and "no later round brought the model to the noise" in one[0].verdict
    rounds = [_round(1, "not in the catalogue", provisional=True), _round(2, "not in the catalogue")]
    settle_provisional(rounds)
    assert not rounds[0].confirmed and rounds[0].outcome == "not in the catalogue"
    # a second effect brings the model to the noise: both confirmed
    rounds = [_round(1, "not in the catalogue", provisional=True), _round(2, "confirmed", confirmed=True)]
    settle_provisional(rounds)
    assert rounds[0].confirmed and rounds[0].outcome == "confirmed" and rounds[1].confirmed
    assert rounds[0].verdict.startswith("effect1 confirmed") and "round 2" in rounds[0].verdict
    # at the next round's refitted base the residual is noise: confirmed
    rounds = [_round(1, "not in the catalogue", provisional=True), _round(2, "nothing significant")]
    settle_provisional(rounds)
    assert rounds[0].confirmed
    # two provisional rounds, none at the noise: neither
    rounds = [_round(1, "x", provisional=True), _round(2, "not in the catalogue", provisional=True)]
    settle_provisional(rounds)
    assert not any(r.confirmed for r in rounds)

