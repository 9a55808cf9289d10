"""A statistical objective for steady running (issue 17, item 2).

In steady running the chain is chaotic: past about half a second a simulation
and a record are uncorrelated sample by sample whatever the parameters
(docs/identification.md), and the paper's Eq. 10-12 compare samples. What
chaos keeps are the statistics of each force over the record. Per channel j
this objective compares

* the spectrum: the log10 power in BANDS (Welch, Hann, 1 s segments) of the
  measured and the simulated force, the RMS difference over the bands in
  decades;
* the amplitude distribution: the QUANTILES of each force, their RMS
  difference over the measured span (as H_j normalises a sample's error);
  the steering wheels' impact peaks are its upper quantiles.

H_j^stat = sqrt(spectrum error^2 + distribution error^2), and f = sum_j
(H_j^stat)^2, as Eq. 10. With the tare the distributions are compared about
their means as far as the transducer's zero tolerance allows (a zero error
within the specification is not the model's).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
from scipy import signal

BANDS = np.geomspace(0.5, 120.0, 11)          # Hz, band edges: 10 bands of equal width in log f
QUANTILES = np.array([0.01, 0.05, 0.25, 0.5, 0.75, 0.95, 0.99])
SEGMENT = 1.0                                  # s, Welch segment
FLOOR = 1e-12                                  # N^2/Hz added before the log (an empty band is not -inf)


def band_log_power(y: np.ndarray, rate: float) -> np.ndarray:
    """log10 of the power in each band (columns of y), shape (bands, channels)."""
    y = np.asarray(y, float)
    nper = int(min(len(y), max(16, round(SEGMENT * rate))))
    f, P = signal.welch(y, fs=rate, window="hann", nperseg=nper, axis=0, detrend="constant")
    df = f[1] - f[0] if len(f) > 1 else rate
    out = []
    for lo, hi in zip(BANDS[:-1], BANDS[1:]):
        m = (f >= lo) & (f < hi)
        out.append(np.log10(np.sum(P[m], axis=0) * df + FLOOR) if m.any() else np.full(y.shape[1], np.log10(FLOOR)))
    return np.array(out)


def stat_errors(measured: np.ndarray, simulated: np.ndarray, rate: float,
                tare: Optional[np.ndarray] = None) -> np.ndarray:
    """H_j^stat per channel (module docstring)."""
    M, S = np.asarray(measured, float), np.asarray(simulated, float)
    span = M.max(axis=0) - M.min(axis=0)
    span = np.where(span > 0, span, 1.0)
    shift = np.zeros(M.shape[1])
    if tare is not None:   # means compared as far as the zero tolerance allows, as `tared` does
        shift = np.clip(M.mean(axis=0) - S.mean(axis=0), -np.asarray(tare), np.asarray(tare))
    qm = np.quantile(M, QUANTILES, axis=0)
    qs = np.quantile(S + shift, QUANTILES, axis=0)
    e_dist = np.sqrt(np.mean(((qm - qs) / span) ** 2, axis=0))
    e_spec = np.sqrt(np.mean((band_log_power(M, rate) - band_log_power(S, rate)) ** 2, axis=0))
    return np.sqrt(e_dist ** 2 + e_spec ** 2)
