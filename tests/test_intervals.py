"""The intervals' claim (identification.objective.uncertainty.intervals) on a
stand-in problem without the FMU: the record's width decides, not the bounds'."""
from __future__ import annotations

import numpy as np
import pytest

from identification.objective.uncertainty import IDENTIFIABLE_WIDTH, Z95, intervals


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
