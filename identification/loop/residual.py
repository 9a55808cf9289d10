"""Residual analysis after an identification: where measured - simulated lives.

After an identification the seven force channels still differ from the
simulation (the paper's NRMSD of 13-32 %). This module asks where: in which
channel, at which stretch of track, at which spatial period (order) and
along which model signal. Pure numpy/scipy; no FMU calls.

    from identification.loop.residual import analyse_residual, describe, to_json
    a = analyse_residual(measured, simulated, times, s, track_length, layout="layout7")
    print(describe(a))                    # Markdown
    json.dump(to_json(a), f)              # JSON-safe summary
    # the figures: lss_app.figures.residual.residual_figures(a, out_dir, measured, simulated)

What is computed (docs/effects.md, section "Residual analysis"):

* per channel: NRMSD (as the objective, identification.objective.problem.nrmsd), its
  share of sum H^2, the mean of the residual (a constant offset is a finding
  of its own) and the share of the mean square it explains;
* the **fold**: residual binned over the track position s mod L (over the
  covered stretch only when the record is shorter than a lap);
* the **order spectrum** over distance: each channel's residual resampled on
  a uniform grid in s, mean and linear trend removed, Hann window, zero
  padded, rfft; amplitudes in N (a sinusoid of amplitude A shows a peak of
  about A), orders in cycles per metre. Named lines: the driving wheel
  1/(2 pi r_d), the cart passage 1/pitch, the motor passage n_motors/L.
  For each: the peak amplitude within half a resolution cell of the line,
  and its ratio to the median spectrum level nearby (line_snr: the higher
  of the medians just below and just above the line, outside its Hann main
  lobe; a line needs 4 cycles in the record to count as resolved);
* the **model signals** (curvature, incline, vertical curvature, motor
  presence, speed, joint speed when given): Pearson correlation with the
  residual and eta^2, the share of the residual variance explained by its
  mean in bins of the signal;
* the **concentration**: the channel with the largest share of sum H^2, the
  window of track (max(pitch, 2 m), at most a quarter of the covered
  length) where that channel's squared residual is densest (its share of
  the squared residual over its share of the samples), the share of the
  squared residual on each kind of track element,
  the strongest named order line, the strongest model signal, and a
  plain-English sentence.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np
from scipy.signal import detrend

from lss_fmu.design import LABELS  # noqa: F401 (the channel names of the figures and tables)
from lss_fmu.variables import FORCE_CHANNELS

from ..objective.problem import nrmsd as _nrmsd

DEFAULT_R_DRIVE = 0.050     # m, wheel types A and B, when r_drive is not given (the FMU's cart.r_drive)
DEFAULT_PITCH = 1.25        # m (lss_fmu.track_geometry.PITCH)
DEFAULT_MOTOR_LENGTH = 0.6  # m (drive.motor_length)
# transducer.s is the arc position of the cart's wheel axle; the motor reaction
# plate (length = pitch) is centred this far behind it (x_axle - x_motor, drive.c)
AXLE_TO_PLATE = 0.40
MIN_WINDOW = 2.0            # m: the concentration window is max(pitch, 2 m) ...
WINDOWS_PER_RECORD = 4      # ... but at most a quarter of the covered length
LINE_SNR_THRESHOLD = 4.0    # a named line at least this far above the nearby median is reported
                            # (white noise: P(peak/median > 4) ~ 2^-16 per independent bin)
UNEVEN_RATIO = 2.0          # window share / its share of the samples at or above this: uneven
LOCALISED_SHARE = 0.5       # ... and holding at least this share of the squared residual: localised
SIGNAL_BINS = 10            # quantile bins of a model signal for eta^2
MIN_SAMPLES = 16
SIDE_CELLS = 8.0            # width of each side band of a line's reference level, resolution cells

KIND_LABEL = {1: "straight", 2: "horizontal curve", 3: "vertical curve", 4: "spiral"}
PLURAL = {"straight": "the straights", "horizontal curve": "the horizontal curves",
          "vertical curve": "the vertical curves", "spiral": "the spirals", "inside a motor": "the motors"}


@dataclass
class ResidualAnalysis:
    channels: list                 # the 7 FORCE_CHANNELS
    times: np.ndarray              # (n,)
    residual: np.ndarray           # (n, 7) measured - simulated
    span: np.ndarray               # (7,) max-min of the measured channel (the NRMSD normaliser)
    nrmsd: np.ndarray              # (7,) per channel
    s: np.ndarray                  # (n,) transducer arc length, unwrapped (m)
    track_length: float
    track: dict                    # per-sample model signals (curvature, incline, motor, v, ...)
    fold: dict                     # residual binned over track position s mod L
    orders: dict                   # order spectrum over distance and named lines
    signals: dict                  # per model signal: correlation and eta^2 per channel
    concentration: dict            # where the residual concentrates, with a sentence
    # -- added (optional) --------------------------------------------------------------
    offset: np.ndarray = None      # (7,) mean of the residual per channel, N
    offset_share: np.ndarray = None  # (7,) offset^2 / mean(residual^2)
    rms: np.ndarray = None         # (7,) RMS of the residual, N
    marks: dict = field(default_factory=dict)  # layout features for figures: joints, elements, motors, runs
    layout_name: Optional[str] = None
    notes: list = field(default_factory=list)  # what was assumed or could not be done


# ----------------------------------------------------------------------------- inputs
def as_matrix(name: str, a, n: Optional[int]) -> np.ndarray:
    cols = getattr(a, "columns", None)
    if cols is not None and all(c in list(cols) for c in FORCE_CHANNELS):
        a = a[FORCE_CHANNELS]
    try:
        m = np.asarray(a, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} is not numeric: {exc}") from None
    k = len(FORCE_CHANNELS)
    if m.ndim != 2 or m.shape[1] != k:
        raise ValueError(f"{name} has shape {m.shape}: expected (n_samples, {k}), the columns in the "
                         f"order of FORCE_CHANNELS ({', '.join(FORCE_CHANNELS)})")
    if n is not None and m.shape[0] != n:
        raise ValueError(f"{name} has {m.shape[0]} samples but measured has {n}: shape mismatch")
    bad = ~np.isfinite(m)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(f"{name} has {int(bad.sum())} non-finite value(s) (NaN or Inf), the first at "
                         f"sample {i}, channel {FORCE_CHANNELS[j]}")
    return m


def _vector(name: str, a, n: int) -> np.ndarray:
    try:
        v = np.asarray(a, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} is not numeric: {exc}") from None
    if v.ndim != 1 or v.shape[0] != n:
        raise ValueError(f"{name} has shape {v.shape}: expected ({n},), one value per sample of measured "
                         f"(shape mismatch)")
    bad = ~np.isfinite(v)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name} has {int(bad.sum())} non-finite value(s) (NaN or Inf), the first at sample {i}")
    return v


def _positive(name: str, x) -> float:
    try:
        x = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {x!r}") from None
    if not (math.isfinite(x) and x > 0):
        raise ValueError(f"{name} = {x}: must be positive and finite")
    return x


def _unwrap_s(s: np.ndarray, length: float, notes: list) -> np.ndarray:
    """s made continuous: drops of about a track length (the FMU's wrap) are
    undone; any other backward step beyond 1 mm is an error."""
    d = np.diff(s)
    wraps = d < -0.5 * length
    if wraps.any():
        d = d + np.where(wraps, length, 0.0)
        notes.append(f"s wrapped {int(wraps.sum())} time(s) at the track length: unwrapped")
    back = d < -1e-3
    if back.any():
        i = int(np.argmax(back)) + 1
        raise ValueError(f"s goes backwards by {-d[i - 1]:.4g} m at sample {i} (s = {s[i]:.6g} m after "
                         f"{s[i - 1]:.6g} m): the transducer cart must move forward along the track")
    out = np.concatenate([[s[0]], s[0] + np.cumsum(d)])
    return np.maximum.accumulate(out)


def _load_layout(layout):
    if layout is None:
        return None
    from lss_fmu.track_geometry import Track
    if isinstance(layout, Track):
        return layout
    from lss_fmu.layout_format import LayoutSpec
    if isinstance(layout, LayoutSpec):
        return Track(layout)
    from lss_fmu.layouts import load_track
    return load_track(layout)


# ----------------------------------------------------------------------------- track signals
def _motor_intervals(motor_positions, track) -> np.ndarray:
    if motor_positions is None:
        return np.asarray(track.motors, float).reshape(-1, 2) if track is not None else np.zeros((0, 2))
    m = np.asarray(motor_positions, dtype=float)
    if m.ndim == 1:
        m = np.stack([m - 0.5 * DEFAULT_MOTOR_LENGTH, m + 0.5 * DEFAULT_MOTOR_LENGTH], axis=1)
    if m.ndim != 2 or m.shape[1] != 2 or not np.all(np.isfinite(m)) or np.any(m[:, 1] < m[:, 0]):
        raise ValueError("motor_positions must be motor centres (k,) or (start, end) intervals (k, 2), finite, "
                         f"start <= end; got shape {m.shape}")
    return m


def _motor_presence(s: np.ndarray, motors: np.ndarray, length: float, pitch: float) -> np.ndarray:
    """1 where the transducer cart's reaction plate overlaps a motor (the motor pushes it)."""
    if len(motors) == 0:
        return np.zeros_like(s)
    plate = s - AXLE_TO_PLATE
    centre = 0.5 * (motors[:, 0] + motors[:, 1])
    half = 0.5 * (motors[:, 1] - motors[:, 0])
    inside = np.zeros(len(s), bool)
    for c, h in zip(centre, half):
        d = np.mod(plate - c + 0.5 * length, length) - 0.5 * length
        inside |= np.abs(d) < 0.5 * pitch + h
    return inside.astype(float)


def _layout_marks(track, motors: np.ndarray) -> dict:
    marks = {"motors": motors.tolist()}
    if track is None:
        return marks
    from lss_fmu.layout_format import KIND_NAMES
    b = track.boundaries()
    marks["length"] = float(track.length)
    marks["joints"] = [float(x) for x in track.s0]
    marks["elements"] = [dict(s0=float(b[k]), s1=float(b[k + 1]), kind=KIND_NAMES[int(track.kind[k])],
                              label=KIND_LABEL[int(track.kind[k])], line=track.lines[k])
                         for k in range(track.n)]
    marks["runs"] = [dict(s0=r.s0, s1=r.s1, spiral=bool(r.spiral), rise=r.rise) for r in track.inclined_runs()]
    return marks


def _track_signals(s, times, track, motors, length, pitch, model_signals, n) -> dict:
    out = {}
    if track is not None:
        heading_rate, incline_rate = track.curvature(s)
        out["curvature"] = heading_rate
        out["incline"] = track.incline(s)
        out["vertical_curvature"] = incline_rate
    if len(motors):
        out["motor"] = _motor_presence(s, motors, length, pitch)
    out["v"] = np.gradient(s, times)
    for name, val in (model_signals or {}).items():
        out[str(name)] = _vector(f"model_signals[{name!r}]", val, n)
    return out


# ----------------------------------------------------------------------------- fold
def _positions(s: np.ndarray, length: float):
    """Track positions to bin: s mod L when the record covers a lap or more,
    else a continuous stretch starting at s[0] mod L (may run past L)."""
    covered = float(s[-1] - s[0])
    if covered >= length * (1 - 1e-9):
        return np.mod(s, length), 0.0, length, True
    start = float(np.mod(s[0], length))
    return start + (s - s[0]), start, covered, False


def _fold(r: np.ndarray, pos: np.ndarray, start: float, span: float, nbins: int) -> dict:
    edges = np.linspace(start, start + span, nbins + 1)
    idx = np.clip(np.searchsorted(edges, pos, side="right") - 1, 0, nbins - 1)
    count = np.bincount(idx, minlength=nbins)
    k = r.shape[1]
    sums = np.stack([np.bincount(idx, weights=r[:, j], minlength=nbins) for j in range(k)], axis=1)
    sq = np.stack([np.bincount(idx, weights=r[:, j] ** 2, minlength=nbins) for j in range(k)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count[:, None] > 0, sums / count[:, None], np.nan)
        rms = np.where(count[:, None] > 0, np.sqrt(sq / np.maximum(count[:, None], 1)), np.nan)
    return dict(edges=edges, centre=0.5 * (edges[1:] + edges[:-1]), mean=mean, rms=rms, count=count,
                start=start, span=span, bin_width=span / nbins)


# ----------------------------------------------------------------------------- orders
def _order_spectrum(r: np.ndarray, s: np.ndarray, notes: list, min_points: int = 4096,
                    pad: int = 4, max_fft: int = 2 ** 18) -> dict:
    ds_all = np.diff(s)
    pos = ds_all > 0
    keep = np.concatenate([[True], pos])
    sk, rk = s[keep], r[keep]
    D = float(sk[-1] - sk[0])
    if len(sk) < MIN_SAMPLES or D <= 0:
        notes.append("too few distinct positions for an order spectrum")
        return dict(order_per_m=np.zeros(0), amplitude=np.zeros((0, r.shape[1])), record_length=D,
                    resolution=float("inf"), bin_spacing=float("nan"), ds=float("nan"), nyquist=0.0,
                    n_points=0, nfft=0, window="hann", detrend="linear")
    ds = float(np.median(np.diff(sk)))
    npts = int(math.floor(D / ds + 1e-9)) + 1
    grid = sk[0] + ds * np.arange(npts)
    D_eff = ds * npts                       # length the DFT sees (resolution 1/D_eff)
    y = np.stack([np.interp(grid, sk, rk[:, j]) for j in range(r.shape[1])], axis=1)
    y = detrend(y, axis=0, type="linear")   # mean (reported as the offset) and trend out
    w = np.hanning(npts + 2)[1:-1]          # Hann without the zero end points
    nfft = 1 << int(math.ceil(math.log2(max(pad * npts, min_points))))
    nfft = max(min(nfft, max_fft), 1 << int(math.ceil(math.log2(npts))))
    X = np.fft.rfft(y * w[:, None], n=nfft, axis=0)
    amp = 2.0 * np.abs(X) / w.sum()
    amp[0] = 0.5 * amp[0]
    f = np.fft.rfftfreq(nfft, d=ds)
    if D_eff < 8.0:
        notes.append(f"short record ({D:.3g} m of track): order resolution {1 / D_eff:.3g} cycles/m; named "
                     f"lines below {4 / D_eff:.3g} cycles/m (4 cycles in the record) are not resolved")
    return dict(order_per_m=f, amplitude=amp, record_length=D, resolution=1.0 / D_eff,
                bin_spacing=float(f[1] - f[0]), ds=ds, nyquist=0.5 / ds, n_points=npts, nfft=nfft,
                window="hann", detrend="linear", main_lobe=2.0 / D_eff)


def _line(spec: dict, f0: float) -> dict:
    """Amplitude at the named order f0 and its ratio to the nearby median level."""
    f, amp = spec["order_per_m"], spec["amplitude"]
    k = amp.shape[1]
    nan = np.full(k, np.nan)
    out = dict(order=float(f0), resolved=False, amplitude=nan, line_snr=nan, noise=nan, peak_order=nan,
               cycles_in_record=float(f0 * spec["record_length"]))
    if len(f) == 0 or not (f0 > 0) or f0 >= spec["nyquist"]:
        out["why"] = "beyond the Nyquist order" if len(f) and f0 >= spec["nyquist"] else "no spectrum"
        return out
    res, lobe = spec["resolution"], spec["main_lobe"]
    # the peak within half a resolution cell of the line; a maximum at the edge
    # of that interval with the spectrum still rising beyond it belongs to a
    # neighbouring feature: then the value at the line's own order is taken
    near = np.abs(f - f0) <= max(0.5 * res, 0.5 * spec["bin_spacing"])
    i_line = int(np.argmin(np.abs(f - f0)))
    near[i_line] = True
    idx = np.where(near)[0]
    i0, i1 = int(idx[0]), int(idx[-1])
    i_peak = idx[np.argmax(amp[idx], axis=0)]
    for c in range(k):
        i = int(i_peak[c])
        if (i == i0 and i0 > 0 and amp[i0 - 1, c] > amp[i0, c]) or \
                (i == i1 and i1 + 1 < len(f) and amp[i1 + 1, c] > amp[i1, c]):
            i_peak[c] = i_line
    peak = amp[i_peak, np.arange(k)]
    # the level nearby: the median on each side of the line, outside its Hann
    # main lobe and above the removed trend's (order 2/D), below Nyquist; the
    # higher of the two is the reference, so a line on a sloping continuum
    # (a pulse, a drift) is not taken for a line. Without a lower side (fewer
    # than 4 cycles in the record) the line is not resolved.
    W = max(SIDE_CELLS * res, 0.25 * f0)
    sides = []
    for lo, hi, need in ((max(f0 - lobe - W, lobe), f0 - lobe, 0.0),
                         (f0 + lobe, min(f0 + lobe + W, spec["nyquist"]), res)):
        m = (f >= lo) & (f <= hi)
        if hi - lo > need and m.sum() >= 2:
            sides.append((np.median(amp[m], axis=0), (lo, hi)))
    if not sides:
        sides = [(np.full(k, np.nan), (float("nan"),) * 2)]
    noise = np.max(np.stack([sd[0] for sd in sides]), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.where(noise > 0, peak / noise, np.where(peak > 0, np.inf, 0.0))
    out.update(resolved=bool(f0 > 2.0 * lobe), amplitude=peak, line_snr=snr, noise=noise, peak_order=f[i_peak],
               bands=[list(map(float, sd[1])) for sd in sides])
    if not out["resolved"]:
        out["why"] = (f"{f0 / res:.2g} cycles in the record, fewer than 4: the line's Hann main lobe "
                      "(+-2 cycles) reaches that of the removed mean and trend")
    return out


# ----------------------------------------------------------------------------- model signals
def _binned(x: np.ndarray, R: np.ndarray, max_bins: int = SIGNAL_BINS) -> dict:
    n = len(x)
    u = np.unique(x)
    if len(u) <= max_bins:
        labels = np.searchsorted(u, x)
        nb = len(u)
    else:
        edges = np.unique(np.quantile(x, np.linspace(0.0, 1.0, max_bins + 1)))
        nb = max(len(edges) - 1, 1)
        labels = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, nb - 1)
    count = np.bincount(labels, minlength=nb)
    used = count > 0
    xc = np.bincount(labels, weights=x, minlength=nb)[used] / count[used]
    k = R.shape[1]
    sums = np.stack([np.bincount(labels, weights=R[:, j], minlength=nb) for j in range(k)], axis=1)[used]
    sq = np.stack([np.bincount(labels, weights=R[:, j] ** 2, minlength=nb) for j in range(k)], axis=1)[used]
    c = count[used][:, None]
    mean = sums / c
    var = np.maximum(sq / c - mean ** 2, 0.0) * c / np.maximum(c - 1, 1)
    sem = np.sqrt(var / c)
    grand = R.mean(axis=0)
    ss_tot = ((R - grand) ** 2).sum(axis=0)
    ss_b = (c * (mean - grand) ** 2).sum(axis=0)
    eta2 = np.where(ss_tot > 0, ss_b / np.where(ss_tot > 0, ss_tot, 1.0), 0.0)
    nbu = int(used.sum())
    null = (nbu - 1) / (n - 1) if n > 1 else 0.0
    return dict(centre=xc, mean=mean, sem=sem, count=count[used], eta2=np.clip(eta2, 0.0, 1.0), eta2_null=null)


def _signal_stats(track: dict, R: np.ndarray) -> dict:
    out = {}
    k = R.shape[1]
    Rc = R - R.mean(axis=0)
    rs = np.sqrt((Rc ** 2).sum(axis=0))
    for name, x in track.items():
        x = np.asarray(x, float)
        sd = float(np.std(x))
        if not (sd > 1e-12 * max(1.0, float(np.max(np.abs(x))))):
            out[name] = dict(constant=True, value=float(np.mean(x)), corr=np.zeros(k), eta2=np.zeros(k),
                             eta2_null=0.0, eta2_adj=np.zeros(k), bins=None)
            continue
        xc = x - x.mean()
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = np.where(rs > 0, (xc @ Rc) / (np.sqrt((xc ** 2).sum()) * np.where(rs > 0, rs, 1.0)), 0.0)
        b = _binned(x, R)
        null = b["eta2_null"]
        adj = np.clip((b["eta2"] - null) / (1.0 - null), 0.0, 1.0) if null < 1 else np.zeros(k)
        out[name] = dict(constant=False, corr=corr, eta2=b["eta2"], eta2_null=null, eta2_adj=adj,
                         bins=dict(centre=b["centre"], mean=b["mean"], sem=b["sem"], count=b["count"]))
    return out


# ----------------------------------------------------------------------------- concentration
def _best_window(e: np.ndarray, pos: np.ndarray, full_lap: bool, length: float, start: float,
                 span: float, w: float) -> dict:
    """Window of width w (over track position) where the squared residual e is
    densest: the largest share of sum(e) relative to the window's share of the
    samples (a stretch covered twice by a record of 1.3 laps is not favoured).
    The window is then centred on the energy centroid if that keeps at least
    95 % of its density (a narrow pulse sits in its middle)."""
    n = len(e)
    total = float(e.sum())
    order = np.argsort(pos, kind="stable")
    ps, es = pos[order], e[order]
    if total <= 0:
        c = start + 0.5 * span
        return dict(start=c - 0.5 * w, end=c + 0.5 * w, centre=c, share=0.0, sample_share=min(1.0, w / span),
                    ratio=0.0)
    if full_lap:
        ps2, es2 = np.concatenate([ps, ps + length]), np.concatenate([es, es])
        starts = np.arange(len(ps))
    else:
        ps2, es2 = ps, es
        starts = np.where(ps <= ps[-1] - w + 1e-12)[0]
        if len(starts) == 0:
            starts = np.array([0])
    cum = np.concatenate([[0.0], np.cumsum(es2)])
    ends = np.searchsorted(ps2, ps2[starts] + w, side="left")
    shares = (cum[ends] - cum[starts]) / total
    samp = (ends - starts) / n
    ratios = shares / np.maximum(samp, 1.0 / n)
    i = int(np.argmax(ratios))
    a, b = int(starts[i]), int(ends[i])
    seg_p, seg_e = ps2[a:b], es2[a:b]
    centre = float(np.sum(seg_p * seg_e) / seg_e.sum()) if seg_e.sum() > 0 else float(ps2[a] + 0.5 * w)
    best = dict(start=float(ps2[a]), share=float(shares[i]), sample_share=float(samp[i]), ratio=float(ratios[i]))
    lo = centre - 0.5 * w
    if full_lap:
        inside = np.mod(pos - lo, length) < w
    else:
        lo = min(max(lo, start), max(start + span - w, start))
        inside = (pos >= lo) & (pos < lo + w)
    if inside.any():
        sh, sa = float(e[inside].sum() / total), float(inside.sum() / n)
        if sh / sa >= 0.95 * best["ratio"]:
            best.update(start=float(lo), share=sh, sample_share=sa, ratio=sh / sa)
    lo = best["start"]
    if full_lap:
        lo, centre = float(np.mod(lo, length)), float(np.mod(centre, length))
    best.update(start=lo, end=lo + w, centre=centre)
    return best


def _by_kind(e: np.ndarray, kinds: Optional[np.ndarray], motor: Optional[np.ndarray]) -> dict:
    """Share of the squared residual on each kind of track element (and inside
    motors) against that kind's share of the samples."""
    out = {}
    total, n = float(e.sum()), len(e)
    groups = {}
    if kinds is not None:
        for k, label in KIND_LABEL.items():
            groups[label] = kinds == k
    if motor is not None:
        groups["inside a motor"] = motor > 0.5
    for label, m in groups.items():
        if not m.any():
            continue
        sh = float(e[m].sum() / total) if total > 0 else 0.0
        sa = float(m.sum() / n)
        out[label] = dict(share=sh, sample_share=sa, ratio=sh / sa)
    return out


def _features_in(marks: dict, lo: float, hi: float, length: float) -> list:
    """Layout features overlapping [lo, hi] (positions mod length)."""
    out = []
    shifts = (-length, 0.0, length) if length else (0.0,)
    for el in marks.get("elements", []):
        if el["kind"] == "straight":
            continue
        if any(el["s0"] + sh < hi and el["s1"] + sh > lo for sh in shifts):
            out.append(f"{el['label']} at {el['s0']:.2f}-{el['s1']:.2f} m (line {el['line']})")
    for m0, m1 in marks.get("motors", []):
        if any(m0 + sh < hi and m1 + sh > lo for sh in shifts):
            out.append(f"motor at {m0:.2f}-{m1:.2f} m")
    for j in marks.get("joints", []):
        if j > 0 and any(lo <= j + sh <= hi for sh in shifts):
            out.append(f"element joint at {j:.2f} m")
    return out


def _concentration(a: ResidualAnalysis, pos, full_lap, start, span, window, pitch, kinds) -> dict:
    H2 = a.nrmsd ** 2
    tot = float(H2.sum())
    share_H = H2 / tot if tot > 0 else np.full(len(H2), 1.0 / len(H2))
    j = int(np.argmax(share_H))
    ch = a.channels[j]
    covered = a.track_length if full_lap else span
    w = window if window is not None else max(pitch, MIN_WINDOW)
    shrunk = False
    if window is None and covered < WINDOWS_PER_RECORD * w:
        w, shrunk = covered / WINDOWS_PER_RECORD, True
    w = min(w, covered) if covered > 0 else w
    e = a.residual[:, j] ** 2
    best = _best_window(e, pos, full_lap, a.track_length, start, span, w)
    ratio = best["ratio"]
    pattern = ("localised" if ratio >= UNEVEN_RATIO and best["share"] >= LOCALISED_SHARE else
               "uneven" if ratio >= UNEVEN_RATIO else "spread")
    stretch = dict(best, width=w, uniform_share=best["sample_share"], pattern=pattern,
                   localised=pattern == "localised", window_shrunk=shrunk,
                   features=_features_in(a.marks, best["start"], best["end"],
                                         a.marks.get("length", a.track_length)))
    by_kind = _by_kind(e, kinds, a.track.get("motor"))
    # strongest named line (resolved ones, any channel), and the strongest on channel j
    line = line_on_channel = None
    best = best_j = -1.0
    for name, ln in a.orders.get("lines", {}).items():
        if not ln.get("resolved"):
            continue
        snr = np.nan_to_num(np.asarray(ln["line_snr"], float), nan=0.0, posinf=1e12)
        jj = int(np.argmax(snr))
        if snr[jj] > best:
            best = float(snr[jj])
            line = dict(name=name, order=ln["order"], frequency_hz=ln.get("frequency_hz"),
                        channel=a.channels[jj], channel_index=jj,
                        amplitude=float(ln["amplitude"][jj]), line_snr=float(ln["line_snr"][jj]),
                        significant=bool(snr[jj] >= LINE_SNR_THRESHOLD))
        if snr[j] > best_j:
            best_j = float(snr[j])
            line_on_channel = dict(name=name, order=ln["order"], amplitude=float(ln["amplitude"][j]),
                                   line_snr=float(ln["line_snr"][j]),
                                   significant=bool(snr[j] >= LINE_SNR_THRESHOLD))
    # strongest model signal on channel j (eta^2 above its independent-sample bias)
    sig = None
    for name, st in a.signals.items():
        if st["constant"]:
            continue
        adj = float(st["eta2_adj"][j])
        if sig is None or adj > sig["eta2_adj"]:
            sig = dict(name=name, eta2=float(st["eta2"][j]), eta2_adj=adj, corr=float(st["corr"][j]))
    out = dict(channel=ch, channel_index=j, share=float(share_H[j]), nrmsd=float(a.nrmsd[j]), nrmsd_total=tot,
               offset=float(a.offset[j]), offset_share=float(a.offset_share[j]),
               shares={c: float(x) for c, x in zip(a.channels, share_H)},
               stretch=stretch, by_kind=by_kind, line=line, line_on_channel=line_on_channel, signal=sig)
    out["sentence"] = _sentence(out)
    return out


def _pct(x: float) -> str:
    """A share in per cent: whole numbers from 10 %, two significant digits below."""
    p = 100.0 * x
    return f"{p:.0f} %" if p >= 10 or p == 0 else f"{p:.2g} %"


def _sentence(c: dict) -> str:
    st = c["stretch"]
    if c["nrmsd_total"] == 0:
        return "Measured and simulated agree exactly: there is no residual."
    parts = [f"The residual is largest in {c['channel']} (NRMSD {c['nrmsd']:.3g}, "
             f"{_pct(c['share'])} of the sum of H^2"]
    if c["offset_share"] >= 0.2:
        parts[0] += (f"; a constant offset of {c['offset']:+.3g} N makes {_pct(c['offset_share'])} "
                     f"of its mean square")
    parts[0] += ")."
    if st["pattern"] == "localised":
        parts.append(f"It concentrates at {st['start']:.2f}-{st['end']:.2f} m of track (centre {st['centre']:.2f} m): "
                     f"{_pct(st['share'])} of that channel's squared residual lies in this {st['width']:.3g} m "
                     f"window, which holds {_pct(st['sample_share'])} of the samples"
                     + ("; there: " + ", ".join(st["features"][:4]) if st["features"] else "") + ".")
    elif st["pattern"] == "uneven":
        parts.append(f"It is uneven along the track: the densest {st['width']:.3g} m window, "
                     f"{st['start']:.2f}-{st['end']:.2f} m, holds {_pct(st['share'])} of that channel's "
                     f"squared residual on {_pct(st['sample_share'])} of the samples ({st['ratio']:.1f} times)"
                     + ("; there: " + ", ".join(st["features"][:4]) if st["features"] else "") + ".")
    else:
        parts.append(f"It is spread along the track: the densest {st['width']:.3g} m window "
                     f"({st['start']:.2f}-{st['end']:.2f} m) holds {_pct(st['share'])} of that channel's "
                     f"squared residual on {_pct(st['sample_share'])} of the samples.")
    kinds = [(k, v) for k, v in c.get("by_kind", {}).items()
             if v["share"] >= 0.2 and 0.02 <= v["sample_share"] < 0.98 and v["ratio"] >= 1.5]
    if kinds:
        k, v = max(kinds, key=lambda kv: kv[1]["ratio"])
        parts.append(f"By track element: {PLURAL.get(k, k)} hold {_pct(v['share'])} of it on "
                     f"{_pct(v['sample_share'])} of the samples.")
    ln = c["line"]
    if ln is not None and ln["significant"]:
        parts.append(f"The strongest order line is the {ln['name']} order ({ln['order']:.3g} cycles/m, "
                     f"{ln['frequency_hz']:.3g} Hz at the mean speed) in {ln['channel']}: {ln['amplitude']:.3g} N, "
                     f"{ln['line_snr']:.1f} times the nearby spectrum.")
    elif ln is not None:
        parts.append(f"No named order line stands out (largest: {ln['name']} in {ln['channel']}, "
                     f"{ln['line_snr']:.1f} times the nearby spectrum; threshold {LINE_SNR_THRESHOLD:g}).")
    else:
        parts.append("No named order line is resolved by this record.")
    sg = c["signal"]
    if sg is not None and sg["eta2_adj"] >= 0.3:
        parts.append(f"Of the model signals, {sg['name']} explains {_pct(sg['eta2'])} of its residual "
                     f"variance (eta^2; correlation {sg['corr']:+.2f}).")
    elif sg is not None:
        parts.append(f"No model signal explains much of it (best: {sg['name']}, eta^2 {sg['eta2']:.2f}).")
    return " ".join(parts)


# ----------------------------------------------------------------------------- the analysis
def analyse_residual(measured, simulated, times, s, track_length, *, layout=None,
                     r_drive: Optional[float] = None, pitch: Optional[float] = None,
                     motor_positions=None, model_signals: Optional[Mapping[str, Sequence[float]]] = None,
                     nbins: Optional[int] = None, window: Optional[float] = None,
                     extra_lines: Optional[Mapping[str, float]] = None) -> ResidualAnalysis:
    """Where measured - simulated lives (module docstring).

    measured, simulated: (n, 7) forces in FORCE_CHANNELS order (arrays or
    DataFrames holding those columns); times: (n,) strictly increasing, s;
    s: (n,) transducer arc length from the simulation (`transducer.s`), m,
    wrapped at the track length or continuous; track_length: m.
    layout: a built-in name, a layout file, a LayoutSpec or a Track: gives
    curvature, incline and motor presence per sample, the pitch and the
    motors. r_drive: the driving wheels' rolling radius (m; the FMU's
    cart.r_drive). pitch (m), motor_positions (centres
    (k,) or intervals (k, 2), m) override it. model_signals: more per-sample
    signals (e.g. 'v_joint'); they replace computed ones of the same name.
    nbins: bins of the fold; window: width of the concentration window, m;
    extra_lines: more named orders {name: cycles per metre}.
    Raises ValueError on bad input, naming the argument."""
    notes: list = []
    M = as_matrix("measured", measured, None)
    n = M.shape[0]
    if n < MIN_SAMPLES:
        raise ValueError(f"measured has {n} samples: at least {MIN_SAMPLES} are needed")
    S = as_matrix("simulated", simulated, n)
    t = _vector("times", times, n)
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0)) + 1
        raise ValueError(f"times is not strictly increasing: sample {i} (t = {t[i]:.6g} s) follows "
                         f"{t[i - 1]:.6g} s")
    L = _positive("track_length", track_length)
    s_raw = _vector("s", s, n)
    su = _unwrap_s(s_raw, L, notes)
    if not su[-1] - su[0] > 0:
        raise ValueError("s does not advance: the transducer cart must move along the track")
    track = _load_layout(layout)
    if track is not None and abs(track.length - L) > 1e-3 * L:
        notes.append(f"track_length {L:.6g} m differs from the layout's {track.length:.6g} m: the geometry is "
                     "taken from the layout at s modulo its own length")
    if pitch is None:
        pitch = track.length / track.n_carts if track is not None else DEFAULT_PITCH
        if track is None:
            notes.append(f"pitch not given: {DEFAULT_PITCH} m assumed")
    pitch = _positive("pitch", pitch)
    if r_drive is None:
        r_drive = DEFAULT_R_DRIVE
        notes.append(f"r_drive not given: {DEFAULT_R_DRIVE} m assumed (wheel types A and B; the FMU's "
                     f"cart.r_drive gives it)")
    r_drive = _positive("r_drive", r_drive)
    if nbins is not None:
        if isinstance(nbins, bool) or int(nbins) != nbins or nbins < 1:
            raise ValueError(f"nbins = {nbins!r}: must be a positive integer")
        nbins = int(nbins)
    if window is not None:
        window = _positive("window", window)
    motors = _motor_intervals(motor_positions, track)

    R = M - S
    span = M.max(axis=0) - M.min(axis=0)
    H = _nrmsd(M, S)
    offset = R.mean(axis=0)
    ms = np.mean(R ** 2, axis=0)
    offset_share = np.where(ms > 0, offset ** 2 / np.where(ms > 0, ms, 1.0), 0.0)
    sig = _track_signals(su, t, track, motors, L, pitch, model_signals, n)

    pos, start, cover, full_lap = _positions(su, L)
    if nbins is None:
        ds_mean = (su[-1] - su[0]) / (n - 1)
        width = max(4.0 * ds_mean, pitch / 8.0)
        nbins = int(min(400, max(16, round(cover / width))))
    fold = _fold(R, pos, start, cover, nbins)
    fold["full_lap"] = full_lap
    fold["laps"] = float((su[-1] - su[0]) / L)

    orders = _order_spectrum(R, su, notes)
    named = {"wheel": 1.0 / (2.0 * math.pi * r_drive), "cart": 1.0 / pitch}
    if len(motors) >= 2:
        named["motor"] = len(motors) / L
        centres = np.sort(np.mod(0.5 * (motors[:, 0] + motors[:, 1]), L))
        gaps = np.diff(np.concatenate([centres, [centres[0] + L]]))
        orders["motor_spacing"] = dict(mean=L / len(motors), min=float(gaps.min()), max=float(gaps.max()))
    for name, f0 in (extra_lines or {}).items():
        named[str(name)] = _positive(f"extra_lines[{name!r}]", f0)
    orders["named"] = named
    orders["lines"] = {name: _line(orders, f0) for name, f0 in named.items()}
    v_mean = float((su[-1] - su[0]) / (t[-1] - t[0]))
    orders["v_mean"] = v_mean
    for ln in orders["lines"].values():
        ln["frequency_hz"] = ln["order"] * v_mean   # a line at a fixed order moves in Hz with the speed
    orders["r_drive"], orders["pitch"] = r_drive, pitch

    a = ResidualAnalysis(channels=list(FORCE_CHANNELS), times=t, residual=R, span=span, nrmsd=H, s=su,
                         track_length=L, track=sig, fold=fold, orders=orders, signals=_signal_stats(sig, R),
                         concentration={}, offset=offset, offset_share=offset_share,
                         rms=np.sqrt(ms), marks=_layout_marks(track, motors),
                         layout_name=(track.spec.name if track is not None else None), notes=notes)
    a.marks.setdefault("length", L)
    kinds = track.kind[track.element_at(su)] if track is not None else None
    a.concentration = _concentration(a, pos, full_lap, start, cover, window, pitch, kinds)
    return a


# ----------------------------------------------------------------------------- reports
def _f(x, nd=3):
    if x is None or not np.isfinite(x):
        return "-"
    return f"{x:.{nd}g}"


def describe(a: ResidualAnalysis) -> str:
    """A short Markdown summary of where the residual is."""
    c = a.concentration
    o = a.orders
    lines = ["### Residual analysis", "",
             f"{len(a.times)} samples over {a.times[-1] - a.times[0]:.3g} s, "
             f"{a.s[-1] - a.s[0]:.3g} m of track ({a.fold['laps']:.2f} laps of {a.track_length:.4g} m"
             + (f", {a.layout_name}" if a.layout_name else "") + ").", "",
             c["sentence"], "",
             "| channel | NRMSD | share of sum H^2 | offset N | offset share | RMS N | strongest line (SNR) "
             "| strongest signal (eta^2) |",
             "|---|---|---|---|---|---|---|---|"]
    for j, ch in enumerate(a.channels):
        best_line, best_snr = "-", -1.0
        for name, ln in o.get("lines", {}).items():
            if ln.get("resolved") and np.isfinite(ln["line_snr"][j]) and ln["line_snr"][j] > best_snr:
                best_line, best_snr = f"{name} ({ln['line_snr'][j]:.1f})", float(ln["line_snr"][j])
        best_sig, best_eta = "-", -1.0
        for name, st in a.signals.items():
            if not st["constant"] and st["eta2"][j] > best_eta:
                best_sig, best_eta = f"{name} ({st['eta2'][j]:.2f})", float(st["eta2"][j])
        lines.append(f"| {ch} | {a.nrmsd[j]:.3g} | {100 * c['shares'][ch]:.0f} % | {a.offset[j]:+.3g} | "
                     f"{100 * a.offset_share[j]:.0f} % | {a.rms[j]:.3g} | {best_line} | {best_sig} |")
    lines.append("")
    if o["n_points"]:
        named = ", ".join(f"{k} {v:.3g}" + ("" if o["lines"][k]["resolved"] else " (not resolved)")
                          for k, v in o["named"].items())
        lines.append(f"Order spectrum: {o['record_length']:.3g} m of record, resolution {_f(o['resolution'])} "
                     f"cycles/m (zero-padded to {o['nfft']} points, bin spacing {_f(o['bin_spacing'])}), "
                     f"Nyquist {_f(o['nyquist'])} cycles/m; named lines (cycles/m): {named}. "
                     f"Line SNR is the peak within half a resolution cell over the median level nearby; "
                     f"{LINE_SNR_THRESHOLD:g} or more counts.")
    else:
        lines.append("No order spectrum (too few distinct positions).")
    if a.notes:
        lines += ["", "Notes: " + "; ".join(a.notes) + "."]
    return "\n".join(lines) + "\n"


def _js(x):
    """JSON-safe: numpy to Python, NaN/Inf to None."""
    if isinstance(x, dict):
        return {str(k): _js(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_js(v) for v in x]
    if isinstance(x, np.ndarray):
        return _js(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        x = float(x)
        return x if math.isfinite(x) else None
    if x is None or isinstance(x, str):
        return x
    if isinstance(x, Path):
        return str(x)
    return str(x)


def to_json(a: ResidualAnalysis) -> dict:
    """JSON-safe summary: per-channel numbers, the fold means, the named lines,
    the signal statistics and the concentration; no per-sample arrays."""
    o = a.orders
    spec = {k: o.get(k) for k in ("record_length", "resolution", "bin_spacing", "ds", "nyquist", "n_points",
                                  "nfft", "window", "detrend", "main_lobe", "r_drive", "pitch", "named",
                                  "motor_spacing") if k in o}
    spec["lines"] = {name: {k: v for k, v in ln.items()} for name, ln in o.get("lines", {}).items()}
    sigs = {name: {k: st[k] for k in ("constant", "corr", "eta2", "eta2_null", "eta2_adj")}
            for name, st in a.signals.items()}
    fold = {k: a.fold[k] for k in ("edges", "mean", "count", "start", "span", "bin_width", "full_lap", "laps")}
    return _js(dict(
        channels=a.channels, n_samples=len(a.times), duration=float(a.times[-1] - a.times[0]),
        s_start=float(a.s[0]), s_end=float(a.s[-1]), track_length=a.track_length, layout=a.layout_name,
        nrmsd=a.nrmsd, objective=float(np.sum(a.nrmsd ** 2)), span=a.span, offset=a.offset,
        offset_share=a.offset_share, rms=a.rms, fold=fold, orders=spec, signals=sigs,
        concentration=a.concentration, notes=a.notes))
