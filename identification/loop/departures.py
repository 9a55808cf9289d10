"""Disturbances outside the catalogue (issue 18): crosstalk between channels, a
periodic interference, a transient pulse, the logger's clock.

Each is fitted to the base residual at its best hypothesis and tested like a
catalogue candidate (identification.loop.evidence.lr_test). A candidate is not
confirmed when one of them explains the residual better, or still explains
a significant part beyond it (`beyond`; identification.loop.verdict).
`named_bands`: the frequencies the catalogue's effects can fill, which the
interference search leaves out.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from lss_fmu.variables import FORCE_CHANNELS

from .evidence import LRTest, fit_gain, lr_test, project_out
from ..objective.problem import tared

log = logging.getLogger(__name__)

CLOCK_MAX = 0.01        # |relative clock error| searched by the clock departure (crystal or RC: within 1 %)
PULSE_WIDTHS = (0.05, 0.1, 0.2)   # s, widths of the transient departure
SHORT = {c: c.replace("transducer.", "") for c in FORCE_CHANNELS}


@dataclass
class Departure:
    """A disturbance no catalogue effect represents, fitted to the base residual."""
    family: str                 # crosstalk, interference, clock
    label: str
    test: LRTest
    detail: dict = field(default_factory=dict)
    columns: list = field(default=None, repr=False, compare=False)   # its signature, off the base columns

    @property
    def counts(self) -> bool:
        """Significant, preferred by BIC, and not at the bound of its search (a
        fit on the bound is no estimate: the clock at CLOCK_MAX stands in for
        something else, e.g. a missing mass slowing the whole transient)."""
        return self.test.significant and self.test.dbic > 0 and not self.detail.get("at_bound", False)

    def to_dict(self) -> dict:
        return {"family": self.family, "label": self.label, "test": self.test.to_dict(), "detail": self.detail}


def beyond(dep: Departure, r_ext: np.ndarray, w: np.ndarray, J: Sequence[np.ndarray] = (),
           looks: int = 1) -> Optional[LRTest]:
    """The departure tested again on a candidate's extended residual r_ext
    (tared), its columns off the columns J (the base's and the effect's): what
    it still explains once the catalogue effect has taken its share, with its own hypotheses times the `looks` taken (the departures
    re-tested; Bonferroni). None without its columns."""
    if not dep.columns:
        return None
    cols = project_out(dep.columns, J, w)
    _, fit, S0, S1 = fit_gain(r_ext, cols, w)
    return lr_test(S0, S1, cols, r_ext - fit, w, dep.test.q, dep.test.m * max(1, looks), dep.test.m_effect,
                   J=J)


def candidate_beyond(dep: Departure, S_b: float, r_ext: np.ndarray, G: Sequence[np.ndarray], w: np.ndarray,
                     q: int, m: int, m_effect: int, J: Sequence[np.ndarray] = ()) -> Optional[LRTest]:
    """The other way round from `beyond`: what a catalogue candidate explains
    once the departure has taken its share. The base with the departure
    (S_b - its dS) against the candidate's extension with the departure fitted
    to its residual r_ext (tared), the candidate's signature columns G off the
    base's J and the departure's; q, m, m_effect the candidate's. A departure
    that beats a candidate by BIC alone may be the better approximation of an
    effect the base cannot follow (a quarter heavier cart, at CoRs that
    compensated: the mass took f from 0.059 to 0.0005, yet a crosstalk scored
    the higher dBIC on its own, smaller scale; docs/close_loop.md); if the
    candidate stays significant beyond it, the record holds more than the
    departure. None without its columns."""
    if not dep.columns or not G:
        return None
    J = list(J)
    cols = project_out(dep.columns, J + list(G), w)
    _, fit, _, S_both = fit_gain(r_ext, cols, w)
    S_dep = max(S_both, S_b - dep.test.dS)
    Gc = project_out(G, J + list(dep.columns), w)
    return lr_test(S_dep, S_both, Gc, r_ext - fit, w, q, m, m_effect, J=J + list(dep.columns))


def _periodogram_peak(x: np.ndarray, fs: float, excluded: Sequence[tuple], f_min: float) -> tuple:
    """(frequency, amplitude) of the largest peak of x's Hann periodogram outside
    the excluded bands [(lo, hi), ...] and below 0.45 fs."""
    n = len(x)
    win = np.hanning(n)
    nfft = 1 << int(math.ceil(math.log2(8 * n)))
    X = np.abs(np.fft.rfft((x - x.mean()) * win, n=nfft))
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    ok = (f >= f_min) & (f <= 0.45 * fs)
    for lo, hi in excluded:
        ok &= ~((f >= lo) & (f <= hi))
    if not ok.any():
        return float("nan"), 0.0
    i = int(np.argmax(np.where(ok, X, -1.0)))
    if 0 < i < len(X) - 1:   # parabolic interpolation of the peak
        a, b, c = X[i - 1], X[i], X[i + 1]
        den = a - 2 * b + c
        shift = 0.5 * (a - c) / den if den != 0 else 0.0
        return float(f[i] + shift * (f[1] - f[0])), float(2 * b / win.sum())
    return float(f[i]), float(2 * X[i] / win.sum())


def departures(problem, x, sim: np.ndarray, r: np.ndarray, J: Sequence[np.ndarray], w: np.ndarray,
               excluded_hz: Sequence[tuple] = (), clock: bool = True) -> list:
    """The departures outside the catalogue, each at its best hypothesis,
    fitted to the base residual r (tared) beyond the base columns J:
    crosstalk (channel k leaking into channel j: the measured F_k added to j;
    42 hypotheses), a periodic interference on one channel (a sinusoid at the
    periodogram's peak outside the frequencies of `excluded_hz`, bands a
    catalogue effect can make; 3 parameters, 7 n/2 hypotheses), a transient on
    one channel (a raised-cosine pulse of PULSE_WIDTHS, where the matched filter
    responds most; 3 parameters, 7 n 3 hypotheses), and the logger's
    clock off by a relative eps (the record's time t is true time t (1 + eps):
    the base simulated at t / (1 + eps), eps scanned within +-CLOCK_MAX; one
    parameter, about 20 simulations). Each with its LRTest (m: its own
    hypotheses)."""
    out = []
    n, k = r.shape
    t = np.asarray(problem.times, float)
    S_b = float(np.sum(r ** 2 * w))
    demean = np.zeros(k, bool)
    if problem.tare is not None:
        demean = np.abs((problem.samples - sim).mean(axis=0)) <= problem.tare
    # crosstalk
    best = None
    for j in range(k):
        for kk in range(k):
            if kk == j:
                continue
            g = np.zeros((n, k))
            g[:, j] = problem.samples[:, kk] - problem.samples[:, kk].mean()
            gt = project_out([g], J, w)
            _, fit, S0, S1 = fit_gain(r, gt, w)
            if best is None or S0 - S1 > best[0]:
                best = (S0 - S1, j, kk, gt, fit)
    if best is not None:
        dS, j, kk, gt, fit = best
        c, *_ = fit_gain(r, gt, w)
        test = lr_test(S_b, S_b - dS, gt, r - fit, w, 1, k * (k - 1), k * (k - 1), J=J)
        out.append(Departure("crosstalk", f"{SHORT[FORCE_CHANNELS[kk]]} into {SHORT[FORCE_CHANNELS[j]]}", test,
                             {"into": FORCE_CHANNELS[j], "from": FORCE_CHANNELS[kk], "factor": float(c[0])}, gt))
    # periodic interference
    fs = 1.0 / float(np.median(np.diff(t))) if n > 1 else 1.0
    f_min = 3.0 / max(t[-1] - t[0], 1e-9)
    best = None
    for j in range(k):
        f0, amp = _periodogram_peak(r[:, j], fs, excluded_hz, f_min)
        if not np.isfinite(f0):
            continue
        cols = []
        for fn in (np.cos, np.sin):
            g = np.zeros((n, k))
            g[:, j] = fn(2 * np.pi * f0 * t)
            cols.append(g)
        gt = project_out(cols, J, w)
        _, fit, S0, S1 = fit_gain(r, gt, w)
        if best is None or S0 - S1 > best[0]:
            best = (S0 - S1, j, f0, gt, fit, amp)
    if best is not None:
        dS, j, f0, gt, fit, amp = best
        m = k * max(1, n // 2)
        test = lr_test(S_b, S_b - dS, gt, r - fit, w, 3, m, m, J=J)
        out.append(Departure("interference", f"{f0:.1f} Hz on {SHORT[FORCE_CHANNELS[j]]}", test,
                             {"channel": FORCE_CHANNELS[j], "frequency_hz": f0, "amplitude_N": amp}, gt))
    # a transient on one channel (a loose cable, a knock): a raised-cosine pulse, the matched
    # filter's largest response over the channels, centres and PULSE_WIDTHS
    best = None
    for width in PULSE_WIDTHS:
        L = int(round(width / max(float(np.median(np.diff(t))), 1e-9))) if n > 1 else 0
        if L < 3 or L > n // 2:
            continue
        kern = 0.5 * (1.0 - np.cos(2 * np.pi * (np.arange(L) + 0.5) / L))
        for j in range(k):
            resp = np.convolve(r[:, j], kern[::-1], mode="valid")   # sum_k r[i + k] kern[k]
            score = resp ** 2 * w[j] / float(kern @ kern)
            i = int(np.argmax(score))
            if best is None or score[i] > best[0]:
                best = (float(score[i]), j, i, L, width, kern)
    if best is not None:
        _, j, i, L, width, kern = best
        g = np.zeros((n, k))
        g[i:i + L, j] = kern
        gt = project_out([g], J, w)
        c, fit, S0, S1 = fit_gain(r, gt, w)
        m = k * n * len(PULSE_WIDTHS)
        test = lr_test(S_b, S1, gt, r - fit, w, 3, m, m, J=J)
        out.append(Departure("pulse", f"{width:g} s pulse on {SHORT[FORCE_CHANNELS[j]]} at t = {t[i + L // 2]:.2f} s",
                             test, {"channel": FORCE_CHANNELS[j], "t": float(t[i + L // 2]), "width_s": width,
                                    "amplitude_N": float(c[0]) if len(c) else 0.0}, gt))
    # the logger's clock
    if clock and n > 8:
        from scipy.optimize import minimize_scalar
        cache = {}

        def S_of(eps):
            if eps not in cache:
                p2 = dataclasses.replace(problem, times=t / (1.0 + eps))
                try:
                    cache[eps] = (float(np.sum(tared(problem.samples - p2.simulate(x), problem.tare) ** 2 * w)),)
                except Exception as exc:
                    log.warning("clock departure at eps = %g failed: %s", eps, exc)
                    cache[eps] = (math.inf,)
            return cache[eps][0]
        try:
            res = minimize_scalar(S_of, bounds=(-CLOCK_MAX, CLOCK_MAX), method="bounded",
                                  options={"xatol": 2e-5, "maxiter": 25})
            eps = float(res.x)
            S_eps = min(S_of(eps), S_b)
            h = 1e-4 if eps < 0 else -1e-4
            p2 = dataclasses.replace(problem, times=t / (1.0 + eps + h))
            p1 = dataclasses.replace(problem, times=t / (1.0 + eps))
            y1 = p1.simulate(x)
            g = (p2.simulate(x) - y1) / h
            g[:, demean] -= g[:, demean].mean(axis=0)
            gt = project_out([g], J, w)
            r_eps = tared(problem.samples - y1, problem.tare)
            test = lr_test(S_b, S_eps, gt, r_eps, w, 1, 1, 1, J=J)
            # and linearised at eps = 0 beyond the base columns, the larger decides (as for a
            # catalogue candidate: the linear fit or the fit with the base held)
            h0 = 1e-4
            g0 = (dataclasses.replace(problem, times=t / (1.0 + h0)).simulate(x) - sim) / h0
            g0[:, demean] -= g0[:, demean].mean(axis=0)
            g0t = project_out([g0], J, w)
            _, fit0, S00, S01 = fit_gain(r, g0t, w)
            t_lin = lr_test(S_b, S01, g0t, r - fit0, w, 1, 1, 1, J=J)
            if t_lin.T > test.T:
                test = t_lin
            out.append(Departure("clock", f"clock {'fast' if eps > 0 else 'slow'} by {abs(eps) * 1e3:.2f} per mille",
                                 test, {"eps": eps, "simulations": len(cache) + 2,
                                        "at_bound": bool(abs(eps) >= 0.98 * CLOCK_MAX)}, g0t))
        except Exception as exc:
            log.warning("clock departure failed: %s", exc)
    return out


def named_bands(v_lo: float, v_hi: float, r_drive: float, pitch: float, n_motors: int, length: float,
                ripple: bool = True, ripple_pitch: tuple = (0.05, 0.23), width: float = 1.0) -> list:
    """Frequency bands (Hz) a catalogue effect can put into a record whose speed
    ranges over [v_lo, v_hi] m/s: the wheel orders 1-6 (out-of-round wheels of up
    to three lobes and their second harmonics),
    the cart passage and the motor passage with their first harmonics, and the
    thrust ripple's band v / pitch over the pole pitches of the catalogue;
    each widened by `width` Hz (the resolution of a short record)."""
    v_lo, v_hi = max(0.0, min(v_lo, v_hi)), max(v_lo, v_hi, 1e-3)
    orders = [k / (2 * math.pi * r_drive) for k in range(1, 7)]
    orders += [k / pitch for k in range(1, 5)]
    if n_motors >= 2:
        orders += [k * n_motors / length for k in range(1, 5)]
    bands = [(o * v_lo - width, o * v_hi + width) for o in orders]
    if ripple:
        bands.append((v_lo / ripple_pitch[1] - width, v_hi / ripple_pitch[0] + width))
    return bands
