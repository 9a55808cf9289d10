"""The noise of the force channels, and whether a residual stands above it (issue 18).

The noise sigma_j of each force channel is declared (meta.json's sensor
block) or estimated from the residual's high-frequency part
(`noise_levels`). A residual is above the noise (`excess`) where its mean
square per channel exceeds sigma_j^2 and a Ljung-Box test rejects whiteness;
one that no candidate explains is "not in the catalogue"
(identification.loop.verdict).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Mapping, Optional

import numpy as np
from scipy import stats

from lss_fmu.variables import FORCE_CHANNELS

log = logging.getLogger(__name__)

ALPHA = 0.01            # family-wise error rate of one round (Bonferroni over the hypotheses scanned)
TRIM = 0.9              # the noise estimate keeps the smallest 90 % of the squared second differences
EXCESS_MIN = 1.5        # a channel is above the noise when its mean square exceeds sigma^2 by this factor ...
LB_LAGS = 20            # ... and a Ljung-Box test over this many lags rejects whiteness (Bonferroni, 7 channels)


@dataclass
class Noise:
    sigma: np.ndarray          # (7,) N, the noise used
    source: str                # "declared" or "estimated"
    estimated: np.ndarray      # (7,) N, the estimate from the residual (reported either way)

    def to_dict(self) -> dict:
        return {"source": self.source, "sigma_N": dict(zip(FORCE_CHANNELS, map(float, self.sigma))),
                "estimated_N": dict(zip(FORCE_CHANNELS, map(float, self.estimated)))}


def _trim_factor(keep: float = TRIM) -> float:
    """E[z^2 | z^2 below its `keep` quantile] for a standard normal z."""
    q = stats.norm.ppf(0.5 + 0.5 * keep)
    return (keep - 2.0 * q * stats.norm.pdf(q)) / keep


def estimate_noise(r: np.ndarray) -> np.ndarray:
    """Per channel, the white noise's standard deviation from the residual's
    high-frequency part: second differences (r_t+1 - 2 r_t + r_t-1 has variance
    6 sigma^2 for white noise; a model error smooth over a few samples hardly
    enters), their squares trimmed of the largest 10 % (impacts)."""
    r = np.asarray(r, float)
    if r.shape[0] < 8:
        return np.full(r.shape[1], np.nan)
    d2 = r[2:] - 2.0 * r[1:-1] + r[:-2]
    q = np.sort(d2 ** 2, axis=0)
    k = max(1, int(TRIM * q.shape[0]))
    var = q[:k].mean(axis=0) / (6.0 * _trim_factor(k / q.shape[0]))
    return np.sqrt(var)


def noise_levels(r: np.ndarray, declared: Optional[Mapping[str, float]] = None,
                 floor: Optional[np.ndarray] = None) -> Noise:
    """The noise of each force channel: declared (meta.json sensor.force_noise_std_N,
    every channel given and positive), else estimated from the residual r."""
    est = estimate_noise(r)
    tiny = 1e-9 if floor is None else np.maximum(np.asarray(floor, float), 1e-9)
    if declared:
        try:
            sig = np.array([float(declared[c]) for c in FORCE_CHANNELS])
            if np.all(np.isfinite(sig)) and np.all(sig > 0):
                return Noise(sig, "declared", est)
        except (KeyError, TypeError, ValueError):
            pass
        log.warning("declared noise %s incomplete: estimated from the residual instead", declared)
    sig = np.where(np.isfinite(est), est, 1.0)
    return Noise(np.maximum(sig, tiny), "estimated", est)


def autocov(rc: np.ndarray, K: int) -> np.ndarray:
    """(K+1, channels) autocovariance of the demeaned residual, lags 0..K (1/n normalised)."""
    n = rc.shape[0]
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    X = np.fft.rfft(rc, n=nfft, axis=0)
    ac = np.fft.irfft(X * np.conj(X), n=nfft, axis=0)[:K + 1] / n
    return ac


@dataclass
class Excess:
    ratio: np.ndarray          # (7,) mean square / sigma^2
    lb_p: np.ndarray           # (7,) Ljung-Box p-values (whiteness)
    above: np.ndarray          # (7,) bool
    S: float                   # sum r^2 / sigma^2
    dof: int

    @property
    def any(self) -> bool:
        return bool(self.above.any())

    def to_dict(self) -> dict:
        return {"ratio": dict(zip(FORCE_CHANNELS, map(float, self.ratio))),
                "ljung_box_p": dict(zip(FORCE_CHANNELS, map(float, self.lb_p))),
                "above": [c for c, a in zip(FORCE_CHANNELS, self.above) if a], "S": self.S, "dof": self.dof,
                "S_per_dof": self.S / max(self.dof, 1)}


def ljung_box(x: np.ndarray, lags: int = LB_LAGS) -> float:
    """p-value of the Ljung-Box test that x is white."""
    n = len(x)
    h = min(lags, n // 4)
    if h < 1:
        return 1.0
    xc = x - x.mean()
    den = float(xc @ xc)
    if den <= 0:
        return 1.0
    ac = autocov(xc[:, None], h)[:, 0] * n / den
    Q = n * (n + 2) * float(np.sum(ac[1:] ** 2 / (n - np.arange(1, h + 1))))
    return float(stats.chi2.sf(Q, h))


def excess(r: np.ndarray, sigma: np.ndarray, n_free: int = 0) -> Excess:
    """Where the residual stands above the noise (module docstring)."""
    ms = np.mean(r ** 2, axis=0)
    ratio = ms / sigma ** 2
    lb = np.array([ljung_box(r[:, j]) for j in range(r.shape[1])])
    above = (ratio >= EXCESS_MIN) & (np.minimum(1.0, r.shape[1] * lb) < ALPHA)
    S = float(np.sum(r ** 2 / sigma ** 2))
    return Excess(ratio, lb, above, S, int(r.size - n_free))
