"""The local refinement that ends each extended identification of the closed
loop (identification.pipeline.refine), on a stand-in problem without the FMU."""
from __future__ import annotations

import types

import numpy as np

from identification.objective.uncertainty import noise_bound
from identification.pipeline.refine import refine


class _Waves:
    """Seven channels a_j sin(w t + phi) + b: nonlinear in w and phi, the
    objective of Eq. 10-12 (weights from the samples' spans)."""
    free = ("a", "w", "phi", "b")

    def __init__(self, truth, bounds, tare=None, noise=0.0):
        self.times = np.arange(0.0, 1.0, 1 / 300)
        self.bounds_array = [tuple(b) for b in bounds]
        self.tare = None if tare is None else np.asarray(tare, float)
        self.nsim = 0
        self.samples = self._model(truth)
        if noise:
            self.samples = self.samples + np.random.default_rng(3).normal(size=self.samples.shape) * noise

    def _model(self, x):
        a, w, phi, b = x
        scale = np.arange(1, 8) / 4.0
        return a * scale * np.sin(w * self.times[:, None] + phi) + b

    def simulate(self, x):
        self.nsim += 1
        return self._model(np.asarray(x, float))

    def f(self, x):
        r = self.samples - self._model(x)
        if self.tare is not None:
            r = r - np.clip(r.mean(0), -self.tare, self.tare)
        span = self.samples.max(0) - self.samples.min(0)
        return float(np.sum(np.mean(r ** 2, 0) / span ** 2))


BOUNDS = [(0.0, 200.0), (20.0, 60.0), (-3.0, 3.0), (-50.0, 50.0)]


def test_refine_walks_to_the_minimum_and_never_goes_uphill():
    truth = np.array([100.0, 40.0, 0.7, 5.0])
    p = _Waves(truth, BOUNDS)
    start = np.array([70.0, 39.4, 0.4, 0.0])
    r = refine(p, start, max_evals=200)
    assert abs(r.f_start - p.f(start)) <= 1e-12 * max(1.0, r.f_start)   # the objective's own metric
    assert r.f <= r.f_start
    assert r.f < 1e-6 * r.f_start
    assert np.allclose(r.x, truth, rtol=1e-3, atol=1e-3), r.x
    assert r.nfev == p.nsim <= 200
    assert np.array_equal(r.sim, p.simulate(r.x))   # the simulation handed back is the one at x


def test_refine_keeps_the_budget_and_the_bounds():
    truth = np.array([100.0, 40.0, 0.7, 5.0])
    p = _Waves(truth, [(0.0, 80.0), (20.0, 60.0), (-3.0, 3.0), (-50.0, 50.0)])   # truth's a outside
    r = refine(p, np.array([60.0, 39.8, 0.6, 0.0]), max_evals=12)
    assert p.nsim == r.nfev <= 12
    lo, hi = np.array(p.bounds_array).T
    assert np.all(r.x >= lo) and np.all(r.x <= hi)
    assert r.f <= r.f_start


def test_refine_leaves_a_zero_error_within_the_tare_alone():
    # the offset b is within the tare on every channel: it is not the model's to explain,
    # and the refinement must not trade the other parameters against it
    truth = np.array([100.0, 40.0, 0.7, 5.0])
    p = _Waves(truth, BOUNDS, tare=np.full(7, 10.0))
    r = refine(p, np.array([90.0, 39.9, 0.6, 0.0]), max_evals=200)
    assert r.f < 1e-8
    assert np.allclose(r.x[:3], truth[:3], rtol=1e-3, atol=1e-3), r.x


class _Pair:
    """A linear least-squares problem in two strongly correlated variables,
    the first with its unconstrained optimum below its lower bound: the
    constrained optimum has it on the bound and the second at its own
    one-variable fit."""
    free = ("u", "v")
    bounds_array = [(0.0, 1.0), (-10.0, 10.0)]
    tare = None

    def __init__(self):
        t = np.linspace(0.0, 1.0, 400)
        self.times = t
        self.A = np.stack([np.sin(3 * t), np.sin(3 * t) + 0.05 * np.cos(7 * t)], axis=1)
        self.samples = np.repeat((self.A @ np.array([-1.0, 2.0]))[:, None], 7, axis=1) * np.arange(1, 8)

    def simulate(self, x):
        return np.repeat((self.A @ np.asarray(x, float))[:, None], 7, axis=1) * np.arange(1, 8)


def test_refine_holds_a_variable_on_its_bound_and_solves_for_the_rest():
    # clipping the joint step would move v as if u had gone below 0; the active set finds the
    # constrained optimum (u on its bound, v the one-variable least squares) in a few steps
    p = _Pair()
    y = p.samples[:, 0]
    v_best = float(p.A[:, 1] @ y / (p.A[:, 1] @ p.A[:, 1]))
    r = refine(p, np.array([0.0, 0.0]), max_evals=40, f_rtol=1e-12)
    assert r.x[0] == 0.0
    assert abs(r.x[1] - v_best) < 1e-6 * abs(v_best), (r.x, v_best)


def test_broyden_update_meets_the_step_and_leaves_the_rest():
    """Broyden's update: the new Jacobian maps the step (scaled to the ranges) onto the change it made,
    and is unchanged on every direction orthogonal to it."""
    from identification.pipeline.refine import _broyden
    rng = np.random.default_rng(5)
    raw = [rng.normal(size=(30, 7)) for _ in range(4)]
    span = np.array([200.0, 40.0, 6.0, 100.0])
    z, dy = rng.normal(size=4), rng.normal(size=(30, 7))
    new = _broyden(raw, z, dy, span)
    G = np.stack(new, axis=-1) * span
    assert np.allclose(G @ z, dy)
    u = rng.normal(size=4)
    u -= (u @ z) / (z @ z) * z
    assert np.allclose(G @ u, (np.stack(raw, axis=-1) * span) @ u)


def test_broyden_and_carried_steps_reach_the_minimum_for_fewer_simulations():
    """Levenberg-Marquardt with the Jacobian differenced once and then updated
    (broyden) reaches the same minimum as differencing it every iteration, in
    fewer simulations; steps carried from a neighbouring problem save the
    scaling of the first Jacobian."""
    truth = np.array([100.0, 40.0, 0.7, 5.0])
    p = _Waves(truth, BOUNDS, noise=0.5)
    start = np.array([92.0, 39.9, 0.62, 3.0])
    full = refine(p, start, max_evals=300, central=True, f_rtol=1e-6)
    n_full = p.nsim
    p.nsim = 0
    upd = refine(p, start, max_evals=300, central=True, f_rtol=1e-6, broyden=True)
    assert upd.f <= full.f * (1 + 1e-3) and np.allclose(upd.x, full.x, rtol=1e-3, atol=1e-3), (upd.x, full.x)
    assert p.nsim < n_full, (p.nsim, n_full)
    assert full.steps is not None and np.all(full.steps > 0)
    p.nsim = 0
    carried = refine(p, start, max_evals=300, central=True, f_rtol=1e-6, steps=full.steps)
    assert np.allclose(carried.x, full.x, rtol=1e-4, atol=1e-4)
    assert p.nsim < n_full, (p.nsim, n_full)


class _Valley:
    """Rosenbrock's valley as a record under the likelihood objective: two
    channels carry 10 (b - a^2) and 1 - a on a waveform, a third carries a
    misfit `floor` (in noise levels) that no (a, b) removes; declared noise on
    all three. Levenberg-Marquardt creeps along the valley in small gains."""
    free = ("a", "b")
    objective = "likelihood"
    tare = None

    def __init__(self, floor: float, sigma: float = 0.05):
        self.times = np.arange(0.0, 1.0, 1 / 300)
        self.bounds_array = [(-2.0, 2.0), (-1.0, 3.0)]
        self.u = np.sqrt(2.0) * np.sin(2 * np.pi * 3 * self.times)
        self.sigma = sigma
        self.noise = np.full(3, sigma)
        self.samples = np.random.default_rng(11).normal(size=(len(self.times), 3)) * sigma
        self.samples[:, 2] += floor * sigma * self.u
        self.nsim = 0

    def simulate(self, x):
        self.nsim += 1
        a, b = np.asarray(x, float)
        s = np.zeros((len(self.times), 3))
        s[:, 0] = -10.0 * (b - a * a) * self.u * self.sigma
        s[:, 1] = -(1.0 - a) * self.u * self.sigma
        return s


VALLEY_START = np.array([-1.2, 1.0])


def test_a_window_whose_pace_cannot_reach_the_noise_is_left_early():
    """With a shorter window to follow, a refinement that at its average
    gain so far could not bring f down to the noise within its budget stops
    (the window will be cut); run to its end it stays above the noise too."""
    p = _Valley(floor=10.0)
    reach = noise_bound(p)
    whole = refine(p, VALLEY_START, max_evals=150, central=True, f_rtol=1e-6, within=None, reach=reach)
    assert not whole.short and whole.f > reach          # the last rung: it runs its course, above the noise
    early = refine(p, VALLEY_START, max_evals=150, central=True, f_rtol=1e-6, within=0.5, reach=reach)
    assert early.short and early.f > reach
    assert early.nfev < 0.5 * whole.nfev, (early.nfev, whole.nfev)
    # the rule as stated: the pace so far, kept up for the iterations left, falls short of `reach`
    left = (150 - early.nfev) // (2 * len(p.free) + 1)
    assert early.f - (early.f_start - early.f) / early.iterations * left > reach
    assert early.f <= early.f_start


def test_a_fit_that_reaches_the_noise_is_not_stopped():
    """The same valley without the misfit: the gains bring f to the noise,
    and the refinement is the one without the rule, bit for bit."""
    p = _Valley(floor=0.0)
    reach = noise_bound(p)
    plain = refine(p, VALLEY_START, max_evals=150, central=True, f_rtol=1e-6)
    ruled = refine(p, VALLEY_START, max_evals=150, central=True, f_rtol=1e-6, within=0.5, reach=reach)
    assert plain.f <= reach
    assert not ruled.short
    assert np.array_equal(ruled.x, plain.x) and ruled.f == plain.f and ruled.nfev == plain.nfev


def test_the_local_stage_before_a_shorter_window_leaves_a_hopeless_refinement():
    from identification.pipeline.identify import local_stage
    p = _Valley(floor=10.0)
    f0 = float(np.sum(np.mean((p.samples - p.simulate(VALLEY_START)) ** 2, axis=0) / p.noise ** 2))
    cut = local_stage(p, VALLEY_START, f0, 150, False, None, shorter=0.5)
    last = local_stage(p, VALLEY_START, f0, 150, False, None)
    assert cut["refined"].get("short_of_noise") is True
    assert "short_of_noise" not in last["refined"]
    assert cut["refined"]["nfev"] < last["refined"]["nfev"]


def test_a_window_left_above_the_noise_before_a_shorter_one_differences_no_interval():
    """Above the noise no interval is claimed whatever the Jacobian says; with
    a shorter window to follow the window is cut, so none is differenced, and
    the shrink stage's test (windowing.troubles) still calls it above the
    noise. On the last rung the intervals are differenced as before."""
    from identification.pipeline.identify import local_stage
    from identification.pipeline.windowing import troubles
    p = _Valley(floor=10.0)
    f0 = float(np.sum(np.mean((p.samples - p.simulate(VALLEY_START)) ** 2, axis=0) / p.noise ** 2))
    def simulations(**kw):
        p.nsim = 0
        out = local_stage(p, VALLEY_START, f0, 150, kw.pop("uncertainty"), None, **kw)
        return out, p.nsim
    cut, n_cut = simulations(uncertainty=True, shorter=0.5)
    assert n_cut == simulations(uncertainty=False, shorter=0.5)[1]   # nothing simulated for the intervals
    assert [iv.method for iv in cut["intervals"]] == ["none", "none"]
    assert all(iv.at_noise is False and not iv.identifiable for iv in cut["intervals"])
    assert troubles(types.SimpleNamespace(intervals=cut["intervals"])) == ["above the noise"]
    last, n_last = simulations(uncertainty=True)
    assert n_last > simulations(uncertainty=False)[1]   # differenced
    assert [iv.method for iv in last["intervals"]] == ["jacobian", "jacobian"]
    assert all(iv.at_noise is False and not iv.identifiable for iv in last["intervals"])
