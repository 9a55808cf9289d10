"""The intervals' claim (identification.objective.uncertainty.intervals) on a
stand-in problem without the FMU: the record's width decides, not the bounds'."""
from __future__ import annotations

import numpy as np
import pytest

from identification.objective.jacobian import jacobian
from identification.objective.uncertainty import (IDENTIFIABLE_WIDTH, ROUGH, Z95, claimable_within,
                                                 inside_stencil, intervals)
from identification.pipeline.refine import refine


class _Line:
    """Seven channels a * g_j(t) + b * h_j(t) with white noise; a weakly
    determined when its gain is small. Pointwise objective (no noise declared)."""
    free = ("a", "b")
    tare = None

    def __init__(self, gain_a: float, bounds, noise: float = 1.0, seed: int = 4):
        self.times = np.arange(0.0, 1.0, 1 / 300)
        self.bounds_array = [tuple(b) for b in bounds]
        self.gain_a = gain_a
        rng = np.random.default_rng(seed)
        self.g = rng.normal(size=(len(self.times), 7))
        self.h = rng.normal(size=(len(self.times), 7))
        self.truth = np.array([0.5 * sum(bounds[0]), 0.5 * sum(bounds[1])])
        self.samples = self.simulate(self.truth) + rng.normal(size=self.g.shape) * noise

    def simulate(self, x):
        a, b = np.asarray(x, float)
        return self.gain_a * a * self.g + b * self.h


def _sd_of_a(p) -> float:
    return {iv.name: iv for iv in intervals(p, p.truth)}["a"].sd


@pytest.mark.parametrize("share", [0.6, 0.3])
def test_a_value_at_a_bound_is_claimed_by_the_record_width_not_the_clipped_one(share):
    """The same record, its value of `a` moved to a bound: clipping halves the
    interval, the claim stays what the record's own width says."""
    bounds = [(0.0, 1.0), (0.0, 1.0)]
    probe = _Line(1.0, bounds)
    sd1 = _sd_of_a(probe)
    # the gain that makes a's 95 % interval `share` of its range wide
    gain = 2 * Z95 * sd1 / share
    p = _Line(gain, bounds)
    inside = {iv.name: iv for iv in intervals(p, p.truth)}["a"]
    at_bound = {iv.name: iv for iv in intervals(p, np.array([1.0, p.truth[1]]))}["a"]
    assert at_bound.upper == 1.0 and at_bound.upper - at_bound.lower < 0.6 * (inside.upper - inside.lower)
    claim = share <= IDENTIFIABLE_WIDTH
    assert inside.identifiable is claim and at_bound.identifiable is claim, (share, inside, at_bound)


class _Bent(_Line):
    """`_Line` with a response in `a` that bends (c (a - a_mid)^2 along a third
    pattern) or, with `chaos`, one that jumps at every scale (a pattern drawn
    afresh for every value of a), as a chaotic record's forces do."""

    def __init__(self, c: float = 0.0, chaos: float = 0.0, **kw):
        self.c, self.chaos = c, chaos
        rng = np.random.default_rng(11)
        self.k = rng.normal(size=(300, 7))
        super().__init__(1.0, [(0.0, 1.0), (0.0, 1.0)], **kw)

    def simulate(self, x):
        a, b = np.asarray(x, float)
        bend = self.c * (a - 0.5) ** 2 * self.k
        if self.chaos:
            bend = bend + self.chaos * np.random.default_rng(np.float64(a).view(np.uint64)).normal(size=self.k.shape)
        return a * self.g + b * self.h + bend


def _rough_of_a(p, recheck=None) -> float:
    sim0 = p.simulate(p.truth)
    w = 1.0 / np.mean((p.samples - sim0) ** 2, axis=0)
    return float(jacobian(p, p.truth, sim0, weights=w, recheck=recheck)[2][0])


def test_a_response_that_bends_is_smooth_at_half_the_step():
    """A curved response parts its forward and backward differences in
    proportion to the step: rough at the first step, smooth at half of it, so
    the variable is claimed with its interval."""
    probe = _rough_of_a(_Bent(c=1.0))
    p = _Bent(c=1.2 / probe)                 # rough 1.2 at the first step: past ROUGH
    assert _rough_of_a(p) >= ROUGH
    assert _rough_of_a(p, recheck=ROUGH) < ROUGH
    a = {iv.name: iv for iv in intervals(p, p.truth)}["a"]
    assert a.smooth and a.identifiable and a.lower <= p.truth[0] <= a.upper, a


def test_a_chaotic_response_stays_rough_at_half_the_step():
    """Differences that jump at every scale do not come together at half the
    step: not smooth, not claimed."""
    p = _Bent(chaos=0.5)
    assert _rough_of_a(p, recheck=ROUGH) >= ROUGH
    a = {iv.name: iv for iv in intervals(p, p.truth)}["a"]
    assert not a.smooth and not a.identifiable, a


class _Kept:
    """Seven channels a_j sin(w t + phi) + b with white noise, each simulation
    kept by its point as problem.simulate keeps it; `runs` counts the ones
    actually computed."""
    free = ("a", "w", "phi", "b")
    tare = None
    bounds_array = [(0.0, 200.0), (20.0, 60.0), (-3.0, 3.0), (-50.0, 50.0)]

    def __init__(self, truth, seed: int):
        self.times = np.arange(0.0, 1.0, 1 / 300)
        self.kept, self.runs = {}, 0
        rng = np.random.default_rng(seed)
        self.samples = self._model(np.asarray(truth, float)) + rng.normal(size=(len(self.times), 7))

    def _model(self, x):
        a, w, phi, b = x
        return a * (np.arange(1, 8) / 4.0) * np.sin(w * self.times[:, None] + phi) + b

    def simulate(self, x):
        key = np.asarray(x, float).tobytes()
        if key not in self.kept:
            self.runs += 1
            self.kept[key] = self._model(np.asarray(x, float))
        return self.kept[key]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_intervals_after_a_refinement_run_nothing_again(seed):
    """The refinement's last central Jacobian, with its optimum inside that
    Jacobian's stencil, gives the intervals from the simulations it kept: none
    run again, and the intervals those of a Jacobian differenced afresh at the
    optimum (the sd within 2 %, the same claims)."""
    truth = np.array([100.0, 40.0, 0.7, 5.0])
    p = _Kept(truth, seed)
    r = refine(p, np.array([90.0, 39.9, 0.6, 3.0]), max_evals=300, central=True, f_rtol=1e-4)
    assert r.at is not None and inside_stencil(r.x, r.at, r.steps), (r.x, r.at, r.steps)
    before = p.runs
    reused = intervals(p, r.x, r.sim, linearised=(r.at, r.steps))
    assert p.runs == before
    fresh = intervals(p, r.x, r.sim)
    assert p.runs > before
    for a, b in zip(reused, fresh):
        assert a.value == b.value and a.identifiable == b.identifiable and a.smooth == b.smooth
        assert abs(a.sd / b.sd - 1.0) < 0.02, (a, b)
        assert a.lower <= truth[p.free.index(a.name)] + 4 * a.sd


def test_intervals_outside_the_stencil_are_differenced_at_the_point():
    """A point farther from the Jacobian's than one step in any variable gets
    its own Jacobian: the stencil's rule, not the caller's say-so."""
    truth = np.array([100.0, 40.0, 0.7, 5.0])
    p = _Kept(truth, 4)
    steps = np.array([1.0, 0.05, 0.01, 0.5])
    far = truth + np.array([0.0, 0.0, 0.02, 0.0])
    assert inside_stencil(truth + 0.5 * steps, truth, steps)
    assert not inside_stencil(far, truth, steps)
    assert not inside_stencil(truth, truth, np.array([1.0, 0.0, 0.01, 0.5]))   # a column without a step
    p.simulate(far)
    before = p.runs
    got = intervals(p, far, linearised=(truth, steps))
    assert p.runs > before + 4
    assert [iv.value for iv in got] == list(far)


def test_a_refinement_watching_a_chaotic_variable_stops_at_its_start():
    """refine's stop_rough: a watched column rough at its step and at half of
    it ends the refinement where it started (no step taken), and the
    intervals from that Jacobian call the variable rough, as they would
    after any refinement; a smooth watched variable lets it walk on."""
    p = _Bent(chaos=0.5)
    x0 = np.array([0.45, 0.55])
    r = refine(p, x0, max_evals=100, central=True, stop_rough=[0])
    assert r.rough == (0,) and np.array_equal(r.x, x0) and r.iterations == 0
    assert r.nfev == 1 + 2 * 2 + 2 + 2    # the start, the Jacobian, its steps scaled, a's two at half the step
    a = {iv.name: iv for iv in intervals(p, r.x, r.sim, linearised=(r.at, r.steps))}["a"]
    assert not a.smooth
    walked = refine(p, x0, max_evals=100, central=True, stop_rough=[1])
    assert walked.rough == () and walked.iterations >= 1 and walked.f < r.f


def test_a_bend_rough_only_at_the_first_step_leaves_the_path_as_it_was():
    """A curved response is rough at the first step and smooth at half of it:
    the rule spends its two simulations and the refinement is the one without
    it, point for point."""
    p = _Bent(c=1.2 / _rough_of_a(_Bent(c=1.0)))
    x0 = np.array([0.47, 0.52])
    plain = refine(p, x0, max_evals=100, central=True)
    watched = refine(p, x0, max_evals=100, central=True, stop_rough=[0, 1])
    assert watched.rough == ()
    assert np.array_equal(plain.x, watched.x) and plain.f == watched.f
    assert watched.nfev == plain.nfev + 2


class _BentCoR(_Bent):
    free = ("contact.e_SW", "b")


def test_the_local_stage_before_a_shorter_window_stops_where_a_cor_is_rough():
    from identification.pipeline.identify import local_stage
    p = _BentCoR(chaos=0.5)
    x0 = np.array([0.45, 0.55])
    f0 = float(np.sum((p.samples - p.simulate(x0)) ** 2))
    cut = local_stage(p, x0, f0, 200, True, None, shorter=0.5)
    assert cut["refined"]["rough_at_start"] == ["contact.e_SW"] and np.array_equal(cut.get("x", x0), x0)
    sw = {iv.name: iv for iv in cut["intervals"]}["contact.e_SW"]
    assert not sw.smooth and sw.claimable_shorter is True
    whole = local_stage(p, x0, f0, 200, True, None)
    assert "rough_at_start" not in whole["refined"] and whole["refined"]["nfev"] > cut["refined"]["nfev"]
    assert {iv.name: iv for iv in whole["intervals"]}["contact.e_SW"].claimable_shorter is None


class _Late(_BentCoR):
    """`_BentCoR` whose response to the CoR, smooth and chaotic parts alike,
    starts at `onset` s: the samples before it hold nothing of it."""

    def __init__(self, onset: float = 0.5, **kw):
        self.onset = onset
        super().__init__(**kw)

    def simulate(self, x):
        a, b = np.asarray(x, float)
        late = (self.times >= self.onset)[:, None]
        return late * (super().simulate(x) - b * self.h) + b * self.h


def test_a_shorter_window_claims_only_what_its_rows_hold():
    """claimable_within: the Jacobian's rows up to the shorter window's end
    decide; a variable whose response starts after it cannot be claimed
    there, one that acts throughout can."""
    p = _Late(onset=0.5)
    sim = p.simulate(p.truth)
    J, steps, _ = jacobian(p, p.truth, sim, weights=1.0 / np.mean((p.samples - sim) ** 2, axis=0))
    res = p.samples - sim
    assert list(claimable_within(p, J, res, steps, 1.0)) == [True, True]
    assert list(claimable_within(p, J, res, steps, 0.4)) == [False, True]
    assert list(claimable_within(p, J, res, steps, 0.0)) == [False, False]   # fewer than two samples


def test_a_rough_cor_the_shorter_window_cannot_claim_does_not_stop_the_refinement():
    """Rough on this window, but its response starts after the shorter
    window's end: that window would not claim it, so the refinement walks on
    (as without a shorter window) and the interval says so."""
    from identification.pipeline.identify import local_stage
    p = _Late(onset=0.5, chaos=0.5)
    x0 = np.array([0.45, 0.55])
    f0 = float(np.sum((p.samples - p.simulate(x0)) ** 2))
    before = local_stage(p, x0, f0, 200, True, None, shorter=0.4)
    assert "rough_at_start" not in before["refined"] and before["refined"]["iterations"] >= 1
    sw = {iv.name: iv for iv in before["intervals"]}["contact.e_SW"]
    assert not sw.smooth and sw.claimable_shorter is False
    after = local_stage(p, x0, f0, 200, True, None, shorter=0.7)   # the response is in that window
    assert after["refined"]["rough_at_start"] == ["contact.e_SW"]
