"""The profile of the least-determined variable (identification.pipeline.base_polish.profile_polish)
on a stand-in problem without the FMU: it scans a variable the record sees, never one it does not."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from identification.pipeline.base_polish import SEEN, profile_polish

T = np.arange(0.0, 0.3, 1 / 300)


@dataclass
class _Three:
    """Seven channels: `strong` scales one pattern, `weak` bends a second one
    with two valleys over its range, `blind` moves nothing (a saturated
    drive's set point on a start-stop's first window). Noise of 1 per sample."""
    free: tuple = ("strong", "blind", "weak")
    x0: dict = field(default_factory=lambda: {"strong": 1.0, "blind": 0.5, "weak": 0.5})
    bounds: dict = field(default_factory=lambda: {"strong": (0.0, 2.0), "blind": (0.0, 1.0), "weak": (0.0, 1.0)})
    tare: object = None
    samples: np.ndarray = None

    def __post_init__(self):
        if self.samples is None:
            rng = np.random.default_rng(5)
            self.samples = self._model({"strong": 1.2, "blind": 0.5, "weak": 0.85}) + rng.normal(size=(len(T), 7))

    @property
    def bounds_array(self):
        return [self.bounds[n] for n in self.free]

    def values(self, x):
        return {**self.x0, **dict(zip(self.free, map(float, x)))}

    def simulate(self, x):
        return self._model(self.values(x))

    @staticmethod
    def _model(v):
        g = np.outer(np.sin(40 * T), np.arange(1, 8)) * 30.0
        h = np.outer(np.cos(25 * T), np.ones(7))
        return v["strong"] * g + 4.0 * np.cos(3 * np.pi * v["weak"]) * h


def test_the_profile_scans_the_least_determined_variable_the_record_sees():
    p = _Three()
    x = np.array([1.0, 0.5, 0.2])   # weak far from any value that gives the truth's response
    xp, S, info = profile_polish(p, x, np.ones(7), points=9)
    assert info["variable"] == "weak", info
    resp = lambda w: np.cos(3 * np.pi * w)   # noqa: E731  (weak's response: several values give it)
    assert S < info["S_start"] and abs(resp(xp[2]) - resp(0.85)) < 0.05, (xp, info)
    assert xp[1] == x[1]   # the blind variable is where it was: nothing moves it


def test_nothing_seen_nothing_scanned():
    p = _Three()
    q = dataclasses.replace(p, free=("blind",))
    x = np.array([0.5])
    xp, S, info = profile_polish(q, x, np.ones(7), points=9)
    assert "variable" not in info and np.array_equal(xp, x) and S == info["S_start"]
    assert SEEN > 0
