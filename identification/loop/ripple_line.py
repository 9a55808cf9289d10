"""The thrust ripple's pitch read off the residual's strongest line (issue 18).

A ripple of pitch p drives every cart at the order 1/p of its own travel, so
the residual shows a line there even where the model's trajectory has
diverged from the record's (docs/close_loop.md, "Why the ripple is missed").
The attribution's scan of pitches, each probed at a fixed thrust, ranks what
the chaotic divergence of that push looks like rather than the ripple's
line, and a pitch off by 1/(3 n) drifts a third of a cycle over a record of
n pitches: the scan's grid is too coarse for a long record, the line is not.

`ripple_lines` returns the lines' pitches to a fraction of the order resolution
(Hann window, zero padding, a parabola through the log amplitude at the peak)
when the line stands out of the residual's own spectrum in the catalogue's
pitch band; the ripple's hypotheses are then built around it
(catalogue.MotorRipple). It only chooses what is tried: the evidence tests
decide, and the Bonferroni correction still counts the whole pitch scan.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LINE_RATIO = 5.0       # the peak against the channel's median (band to Nyquist): below it no line is claimed
MIN_CYCLES = 4.0       # cycles of the line in the record (fewer: it merges with the removed trend)
PAD = 16               # zero padding (points of the transform per point of the record)
MAX_LINES = 3          # the strongest line is not always the ripple's (a chaotic misfit's peak can lead)


@dataclass
class RippleLine:
    pitch: float        # m
    order: float        # cycles per m of the transducer cart's travel
    ratio: float        # peak / the channel's median amplitude from the band's lower edge to Nyquist
    resolution: float   # cycles per m: 1 / the record's length of track

    @property
    def relative_cell(self) -> float:
        """The order resolution relative to the line's order (the pitch's scale of doubt)."""
        return self.resolution / self.order


def ripple_lines(r: np.ndarray, s: np.ndarray, pitch_range: tuple) -> list:
    """The strongest lines (at most MAX_LINES, a resolution cell apart, the
    strongest first) of the residual `r` (samples x channels) in the order
    domain of the track position `s` (unwrapped, m), each channel's peak
    within the orders of `pitch_range` (m) against that channel's median
    from the band's lower edge to Nyquist; empty if the record is too
    short, the cart does not move or no peak stands LINE_RATIO above its
    median. White noise claims a line in about 1 record of 200."""
    s = np.asarray(s, float)
    r = np.asarray(r, float)
    if s.ndim != 1 or len(s) != len(r) or len(s) < 16 or not np.all(np.isfinite(s)):
        return []
    keep = np.concatenate([[True], np.diff(s) > 0])
    sk, rk = s[keep], r[keep]
    D = float(sk[-1] - sk[0]) if len(sk) > 1 else 0.0
    if len(sk) < 16 or D <= 0:
        return []
    ds = D / (len(sk) - 1)
    grid = sk[0] + ds * np.arange(len(sk))
    y = np.stack([np.interp(grid, sk, rk[:, j]) for j in range(r.shape[1])], axis=1)
    t = np.arange(len(grid), dtype=float)
    for j in range(y.shape[1]):   # mean and trend out: what remains of the base's misfit is not a line
        y[:, j] -= np.polyval(np.polyfit(t, y[:, j], 1), t)
    win = np.hanning(len(grid) + 2)[1:-1]
    nfft = 1 << int(math.ceil(math.log2(PAD * len(grid))))
    spec = np.abs(np.fft.rfft(y * win[:, None], n=nfft, axis=0))
    order = np.fft.rfftfreq(nfft, d=ds)
    lo = max(1.0 / pitch_range[1], MIN_CYCLES / D)
    hi = min(1.0 / pitch_range[0], 0.5 / ds)
    band = (order >= lo) & (order <= hi)
    if band.sum() < 8:
        return []
    idx = np.where(band)[0]
    # the reference level: the median from the band's lower edge to Nyquist, the sensor's noise
    # floor where the model follows the record (the chaotic misfit sits at the low orders)
    ref = order >= lo
    # per channel: a ripple shows on the channels it drives (the joint's axial force first), and
    # the chaotic part of the others' misfit would bury it in a sum over channels
    peaks = []
    for j in range(spec.shape[1]):
        a = spec[:, j]
        med = float(np.median(a[ref]))
        k = int(idx[np.argmax(a[idx])])
        ratio = float(a[k] / med) if med > 0 else 0.0
        if ratio >= LINE_RATIO:
            peaks.append((ratio, _interpolated(a, order, k)))
    out = []
    for ratio, f_k in sorted(peaks, reverse=True):
        if all(abs(f_k - o.order) > 1.0 / D for o in out):
            out.append(RippleLine(1.0 / f_k, f_k, ratio, 1.0 / D))
        if len(out) == MAX_LINES:
            break
    return out


def _interpolated(amp: np.ndarray, order: np.ndarray, k: int) -> float:
    """The peak between bins: a parabola through the log amplitude (exact for a
    Gaussian lobe, within a few per cent of a bin for the zero-padded Hann's)."""
    f_k = float(order[k])
    if 0 < k < len(amp) - 1 and np.all(amp[k - 1:k + 2] > 0):
        a, b, c = np.log(amp[k - 1:k + 2])
        den = a - 2 * b + c
        if den < 0:
            f_k += float(np.clip(0.5 * (a - c) / den, -0.5, 0.5)) * float(order[1] - order[0])
    return f_k
