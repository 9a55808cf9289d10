"""Where a residual sits (issue 18): channel, time, track position, frequency
and order (`localise`), the model's own signals along the record, the
residual analysis (identification.loop.residual), what the catalogue needs to
know of the record (`context`) and the frequency bands its effects can fill."""
from __future__ import annotations

import logging
import math
from typing import Optional, Sequence

import numpy as np

from lss_fmu.variables import FORCE_CHANNELS

from .attribution import simulate_with
from .catalogue import Context
from .departures import named_bands
from ..objective.problem import IdentificationProblem

log = logging.getLogger(__name__)

LOCAL_SHARE = 0.5    # unexplained residual 'concentrates' if half of it sits in ...
LOCAL_WINDOW = 0.1   # ... this fraction of the record (or 0.1 s, whichever is longer) of one channel
SIGNALS = ["transducer.s", "transducer.v", "transducer.joint.v_axial"]


def context(problem: IdentificationProblem, x: np.ndarray, sensor_offset_std: Optional[dict] = None,
            noise: Optional[np.ndarray] = None, s: Optional[np.ndarray] = None) -> Context:
    """What the catalogue needs; `sensor_offset_std` (N per force channel) is the
    transducer's declared zero tolerance (meta.json 'sensor'), by default the
    virtual transducer cart's; `noise` the white noise per channel (N); `s`
    the transducer cart's simulated track position over the record (unwrapped),
    else estimated from the set point (wrong for a start-up or a stop)."""
    from lss_fmu.layouts import load_track
    tr = load_track(problem.layout)
    vals = problem.values(x)
    v = float(vals.get("drive.v_ref", problem.fixed.get("drive.v_ref", 2.0)))
    s0 = float(vals.get("trigger.s_M", 0.0))
    window = (float(s[0]), float(s[-1])) if s is not None and len(s) else (s0, s0 + v * float(problem.times[-1]))
    ctx = Context(problem.layout, float(tr.length), np.asarray(tr.s0, float), window, int(tr.n_carts), v)
    if sensor_offset_std:
        ctx.sensor_offset_tol = 3.0 * np.array([float(sensor_offset_std[c]) for c in FORCE_CHANNELS])
    elif problem.tare is not None:
        ctx.sensor_offset_tol = np.asarray(problem.tare, float)
    if noise is not None:
        ctx.sensor_noise = np.asarray(noise, float)
    return ctx


def localise(problem: IdentificationProblem, r: np.ndarray, s: Optional[np.ndarray] = None,
             w: Optional[np.ndarray] = None) -> dict:
    """Where the residual concentrates: the channel with the largest share of
    the weighted squared residual (w per channel, by default the objective's
    1 / span^2; with 1 / sigma^2 the share of the excess over the noise), the
    shortest stretch of the record holding LOCAL_SHARE of it, and the
    channel's dominant frequency (the periodogram's peak, against its median)."""
    if w is None:
        w = 1.0 / np.maximum(problem.samples.max(0) - problem.samples.min(0), 1e-12) ** 2
    e = r ** 2 * w
    per_ch = e.sum(0)
    j = int(np.argmax(per_ch))
    t = problem.times
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    n = max(2, int(round(max(LOCAL_WINDOW * (t[-1] - t[0]), 0.1) / dt)))
    n = min(n, len(t))
    c = np.concatenate([[0.0], np.cumsum(e[:, j])])
    win = c[n:] - c[:-n]
    i = int(np.argmax(win))
    share = float(win[i] / c[-1]) if c[-1] > 0 else 0.0
    out = {"channel": FORCE_CHANNELS[j], "channel_share": float(per_ch[j] / per_ch.sum()) if per_ch.sum() > 0 else 0.0,
           "t_start": float(t[i]), "t_end": float(t[i + n - 1]), "window_share": share,
           "window_fraction": n / len(t)}
    if s is not None:
        out.update({"s_start": float(s[i]), "s_end": float(s[i + n - 1])})
    out["concentrated"] = bool(share >= LOCAL_SHARE and share >= 3 * out["window_fraction"])
    # the dominant frequency of that channel's residual
    x = r[:, j] - r[:, j].mean()
    if len(x) >= 16:
        nfft = 1 << int(math.ceil(math.log2(8 * len(x))))
        X = np.abs(np.fft.rfft(x * np.hanning(len(x)), n=nfft))
        f = np.fft.rfftfreq(nfft, dt)
        ok = f >= 3.0 / max(t[-1] - t[0], 1e-9)
        if ok.any():
            k = int(np.argmax(np.where(ok, X, -1.0)))
            med = float(np.median(X[ok]))
            out["frequency_hz"] = float(f[k])
            out["frequency_peak_ratio"] = float(X[k] / med) if med > 0 else float("inf")
            if s is not None and t[-1] > t[0] and abs(s[-1] - s[0]) > 0:
                out["order_per_m"] = float(f[k] / (abs(s[-1] - s[0]) / (t[-1] - t[0])))
    # is the residual's energy growing with time (a clock, a drift)?
    halves = np.array_split(e[:, j], 2)
    if len(halves) == 2 and halves[0].sum() > 0:
        out["late_to_early"] = float(halves[1].sum() / halves[0].sum())
    return out


def signals_at(problem, x) -> dict:
    try:
        sig = simulate_with(problem, x, channels=SIGNALS)
    except Exception as exc:  # older FMU without the diagnostic outputs: the track position alone
        log.warning("model signals unavailable (%s); using transducer.s only", exc)
        sig = np.column_stack([simulate_with(problem, x, channels=["transducer.s"])[:, 0]] +
                              [np.full(len(problem.times), np.nan)] * 2)
    return dict(zip(SIGNALS, sig.T))


def unwrap(s: np.ndarray, length: float) -> np.ndarray:
    jumps = np.diff(s) < -0.5 * length
    return s + length * np.concatenate([[0], np.cumsum(jumps)])


def analyse(problem: IdentificationProblem, x: np.ndarray, sim: np.ndarray, signals: Optional[dict] = None):
    """The residual analysis at x (None if the module or the layout lacks what it needs)
    and the transducer cart's unwrapped track position."""
    from lss_fmu.layouts import load_track
    try:
        from .residual import analyse_residual
    except ImportError:
        return None, None
    sig = signals if signals is not None else signals_at(problem, x)
    tr = load_track(problem.layout)
    s = unwrap(sig["transducer.s"], float(tr.length))
    r_drive = float(problem.model_constants(("cart.r_drive",))["cart.r_drive"])
    model_signals = {"v": sig["transducer.v"], "v_joint": sig["transducer.joint.v_axial"]}
    model_signals = {k: v for k, v in model_signals.items() if np.all(np.isfinite(v))}
    try:
        ra = analyse_residual(problem.samples, sim, problem.times, s, float(tr.length), layout=problem.layout,
                              r_drive=r_drive, pitch=float(tr.length) / tr.n_carts,
                              motor_positions=np.asarray(tr.motors), model_signals=model_signals)
    except Exception as exc:
        log.warning("residual analysis failed: %s", exc)
        ra = None
    return ra, s


def catalogue_bands(problem: IdentificationProblem, sig: dict, effects: Sequence[str]) -> list:
    """Frequency bands (Hz) the catalogue's effects can fill in this record
    (departures.named_bands at the record's speeds)."""
    from lss_fmu.layouts import load_track
    try:
        tr = load_track(problem.layout)
        v = np.asarray(sig.get("transducer.v"), float)
        v = v[np.isfinite(v)]
        if not len(v):
            v = np.array([float((problem.x0 or {}).get("drive.v_ref", problem.fixed.get("drive.v_ref", 2.0)))])
        r_drive = float(problem.model_constants(("cart.r_drive",))["cart.r_drive"])
        return named_bands(float(np.min(np.abs(v))), float(np.max(np.abs(v))), r_drive,
                           float(tr.length) / int(tr.n_carts), len(tr.motors), float(tr.length),
                           ripple="motor_ripple" in effects)
    except Exception as exc:
        log.warning("catalogue frequency bands unavailable: %s", exc)
        return []


def where_text(loc: dict) -> str:
    parts = [f"{loc['channel']} ({100 * loc['channel_share']:.0f}% of the excess)"]
    if "frequency_hz" in loc:
        fr = f"{loc['frequency_hz']:.1f} Hz"
        if "order_per_m" in loc:
            fr += f" ({loc['order_per_m']:.2f} cycles/m)"
        parts.append(f"dominant frequency {fr}, {loc['frequency_peak_ratio']:.0f} x the median spectrum")
    tw = f"t = {loc['t_start']:.2f}-{loc['t_end']:.2f} s"
    if "s_start" in loc:
        tw += f", track s = {loc['s_start']:.2f}-{loc['s_end']:.2f} m"
    parts.append(f"densest at {tw} ({100 * loc['window_share']:.0f}% of that channel's excess"
                 f"{', concentrated' if loc['concentrated'] else ''})")
    if loc.get("late_to_early") is not None:
        parts.append(f"second half / first half of the record {loc['late_to_early']:.1f}")
    return "; ".join(parts)
