"""What a record can reveal of an effect (identification.loop.reach).

The rule under test: an effect of size a_90 in a given configuration passes
the loop's white-noise test (Bonferroni and BIC) in 90 % of records; checked
by drawing the records, not by restating the formula. Then the effects'
unit configurations, the ladder rule and the verdict's sentence.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from identification.loop.attribution import Attribution, HypothesisScore, _complement
from identification.loop.catalogue import CATALOGUE, Hypothesis, Probe, WheelOutOfRound
from identification.loop.reach import lambda_90, reach, threshold, unseen_text


def _score(effect: str, hyp: Hypothesis, info: np.ndarray) -> HypothesisScore:
    return HypothesisScore(effect, hyp.label, 0.0, 0.0, np.zeros(len(hyp.probes)), np.zeros(len(hyp.probes)), hyp,
                           information=np.atleast_2d(info))


def _resistance_hypothesis() -> Hypothesis:
    return CATALOGUE["resistance"].hypotheses(None)[0]


@pytest.mark.parametrize("seed", [1, 2])
def test_an_effect_at_a90_passes_the_test_in_nine_records_of_ten(seed):
    """Linear signature g beside base columns J, white noise: the record with the
    effect at a_90 must give dS = S(J) - S(J, g) above the threshold in 90 %."""
    rng = np.random.default_rng(seed)
    n, ch = 300, 2
    sigma = np.array([2.0, 5.0])
    J = [rng.normal(size=(n, ch)) for _ in range(3)]
    g = rng.normal(size=(n, ch)) + 0.5 * J[0]          # partly what the base can do
    w = 1.0 / sigma ** 2
    F = _complement(J, w)([g])
    hyp = _resistance_hypothesis()
    m, counts = 40, {"resistance": 1}
    (r,) = reach(Attribution(0.0, 0.0, [], [_score("resistance", hyp, F)]), n * ch, m, counts, 1.0)
    assert r.q == 1 and r.best == pytest.approx(r.typical)
    c = threshold(n * ch, m, 1, 1)
    assert r.threshold == pytest.approx(c)

    def S(res, cols):
        A = np.stack([(col * np.sqrt(w)).ravel() for col in cols], axis=1)
        b = (res * np.sqrt(w)).ravel()
        coef, *_ = np.linalg.lstsq(A, b, rcond=None)
        e = b - A @ coef
        return float(e @ e)

    draws = 600
    passed = 0
    for _ in range(draws):
        res = r.typical * g + rng.normal(size=(n, ch)) * sigma + J[1] * rng.normal()
        passed += S(res, J) - S(res, J + [g]) > c
    rate = passed / draws
    assert abs(rate - 0.9) < 4 * math.sqrt(0.09 / draws), rate      # 0.9 within 4 binomial sd
    # at half of it the test mostly fails: the bound is not loose
    assert lambda_90(c, 1) / 4 < c


def test_the_effects_configurations_have_unit_size():
    oor = WheelOutOfRound()
    for hyp in oor.hypotheses(None):
        d = oor.directions(hyp)
        assert d.shape == (oor.PHASE_GRID ** 2, 4)
        for row in d:
            lc, ls, rc, rs = oor.sides(row)
            assert math.hypot(lc, ls) == pytest.approx(1.0) and math.hypot(rc, rs) == pytest.approx(1.0)
    ripple = CATALOGUE["motor_ripple"]
    hyp = ripple._hypothesis(0.1, ripple.PROBE)
    d = ripple.directions(hyp)
    assert np.allclose(np.hypot(d[:, 0], d[:, 1]), 1.0)
    assert CATALOGUE["sensor"].directions(CATALOGUE["sensor"].hypotheses(_ctx())[0]) is None
    for name, eff in CATALOGUE.items():
        assert (eff.PLAUSIBLE is None) == (name == "sensor")


def _ctx():
    from identification.loop.catalogue import Context
    return Context("layout7", 100.0, np.array([0.0]), (0.0, 1.0), 52, 2.0)


def test_a_ladder_rung_counts_at_its_own_size_only():
    """A joint's play: the smallest rung whose own signature reaches lambda_90."""
    clr = CATALOGUE["joint_clearance"]
    hyps = clr.hypotheses(None)
    n, m = 1000, 30
    c = threshold(n, m, len(hyps), 1)
    lam = lambda_90(c, 1)
    rung = 9
    scores = []
    for k, h in enumerate(hyps):
        gap = h.probes[0].params[clr.LADDER]
        # the rungs below `rung` carry half the information their size needs, the others twice
        info = (0.5 if k < rung else 2.0) * lam / gap ** 2
        scores.append(_score("joint_clearance", h, np.array([[info]])))
    (r,) = reach(Attribution(0.0, 0.0, [], scores), n, m, {"joint_clearance": len(hyps)}, 1.0)
    assert r.typical == pytest.approx(hyps[rung].probes[0].params[clr.LADDER])


def test_the_verdict_names_only_what_the_record_cannot_reveal():
    hyp = _resistance_hypothesis()
    plaus = CATALOGUE["resistance"].PLAUSIBLE
    c = threshold(600, 10, 1, 1)
    lam = lambda_90(c, 1)
    seen = reach(Attribution(0.0, 0.0, [], [_score("resistance", hyp, np.array([[4 * lam / plaus ** 2]]))]),
                 600, 10, {}, 2.0)
    assert seen[0].visible and unseen_text(seen) is None
    hidden = reach(Attribution(0.0, 0.0, [], [_score("resistance", hyp, np.array([[lam / (3 * plaus) ** 2]]))]),
                   600, 10, {}, 2.0)
    assert not hidden[0].visible
    assert hidden[0].typical == pytest.approx(3 * plaus)
    assert hidden[0].seconds_needed == pytest.approx(18.0)      # 9 times the information: 9 times the time
    assert hidden[0].share == 0.0
    text = unseen_text(hidden)
    assert "resistance" in text and "18 s" in text and f"revealed only from {3 * plaus:.3g} N.s/m" in text
    assert hidden[0].to_dict()["visible"] is False


def test_a_place_bound_effect_reports_the_share_of_places_that_show():
    """A track bump is felt where a cart passes its joint: the share of joints
    and lengths where a plausible bump shows, and no running-time estimate."""
    bump = CATALOGUE["track_bump"]
    ctx = _ctx()
    ctx.element_starts = np.arange(10) * 3.0
    hyps = bump.hypotheses(ctx)
    c = threshold(900, 100, len(hyps), 2)
    lam = lambda_90(c, 2)
    # a fifth of the hypotheses see a bump of a tenth of the plausible size, the others nothing
    scores = [_score("track_bump", h, np.array([[lam / (0.1 * bump.PLAUSIBLE) ** 2 if k % 5 == 0 else 0.0]]))
              for k, h in enumerate(hyps)]
    (r,) = reach(Attribution(0.0, 0.0, [], scores), 900, 100, {"track_bump": len(hyps)}, 1.5)
    assert r.share == pytest.approx(0.2) and not r.visible
    assert r.best == pytest.approx(0.1 * bump.PLAUSIBLE)
    assert r.seconds_needed is None and "passes more of the track" in r.text() and "20 %" in r.text()


def test_a_runouts_lobes_are_judged_apart():
    oor = CATALOGUE["wheel_oor"]
    hyps = oor.hypotheses(None)
    c = threshold(900, 100, len(hyps), 4)
    lam = lambda_90(c, 4)
    # one lobe: plausible size needs 4 times the information there is; two and three: plenty
    scores = [_score("wheel_oor", h, np.eye(4) * lam / oor.PLAUSIBLE ** 2 * (0.25 if k == 0 else 100.0))
              for k, h in enumerate(hyps)]
    R = {r.kind: r for r in reach(Attribution(0.0, 0.0, [], scores), 900, 100, {"wheel_oor": 3}, 1.0)}
    assert set(R) == {"1 lobe", "2 lobes", "3 lobes"}
    assert not R["1 lobe"].visible and R["2 lobes"].visible and R["3 lobes"].visible
    assert "wheel_oor (1 lobe)" in unseen_text(list(R.values())) and "2 lobes" not in unseen_text(list(R.values()))


def test_a_hypothesis_without_information_has_no_reach():
    """An effect whose probes the base columns absorb entirely reaches no size."""
    rng = np.random.default_rng(0)
    J = [rng.normal(size=(50, 2)) for _ in range(2)]
    F = _complement(J, np.ones(2))([2.0 * J[0] - J[1]])
    assert F[0, 0] == 0.0
    hyp = Hypothesis("resistance", "viscous", [Probe("c1", {}, 1.0)])
    (r,) = reach(Attribution(0.0, 0.0, [], [_score("resistance", hyp, F)]), 100, 5, {}, 1.0)
    assert not math.isfinite(r.typical) and not r.visible and "no longer record" in r.text()
