"""Figures of a residual analysis (identification.loop.residual), PNG and SVG.

    from lss_app.figures.residual import residual_figures
    paths = residual_figures(analysis, "out/mNN/residual", measured, simulated)

1. residual_time    residual per channel over time, its mean dashed, track
                    elements shaded, track position on the top axis
2. residual_fold    residual binned over the track position (mean, RMS),
                    curves / spirals / vertical curves shaded, element joints
                    dotted, motors and level changes as bars, the window where
                    the residual concentrates bracketed
3. residual_orders  order spectrum per channel (cycles per metre), the named
                    lines marked, the unresolved low orders shaded
4. residual_signals correlation and eta^2 heat maps (channels x model
                    signals), and the binned mean residual of the leading
                    channel against each signal with standard-error bars
5. residual_forces  (when measured and simulated are given) the two overlaid
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import FuncFormatter, NullFormatter  # noqa: E402

from identification.loop.residual import LINE_SNR_THRESHOLD, ResidualAnalysis, as_matrix  # noqa: E402
from lss_fmu.design import LABELS  # noqa: E402

KIND_COLOUR = {"curve": "0.88", "spiral": "#cfe0f5", "vcurve": "#fbe3c8"}
KIND_NAME = {"curve": "horizontal curve", "spiral": "spiral", "vcurve": "vertical curve"}
MOTOR_COLOUR, LEVEL_COLOUR, WINDOW_COLOUR = "#2a9d4b", "#f4a259", "#c0392b"
LINE_COLOUR = {"wheel": "#d62728", "cart": "#1f77b4", "motor": "#2a9d4b"}


def _save(fig, out_dir: Path, stem: str, formats: Sequence[str]) -> list:
    paths = []
    for fmt in formats:
        path = out_dir / f"{stem}.{fmt}"
        fig.savefig(path, dpi=110, metadata={"Date": None} if fmt == "svg" else {})
        paths.append(path)
    plt.close(fig)
    return paths


def _intervals(marks: dict, lo: float, hi: float):
    """Layout intervals (s0, s1, kind) shifted by whole laps into [lo, hi]."""
    L = marks.get("length")
    if not L:
        return []
    out = []
    for el in marks.get("elements", []):
        for k in range(int(np.floor((lo - el["s1"]) / L)), int(np.ceil((hi - el["s0"]) / L)) + 1):
            a, b = el["s0"] + k * L, el["s1"] + k * L
            if b > lo and a < hi:
                out.append((max(a, lo), min(b, hi), el["kind"]))
    return out


def _shifted(points, L: Optional[float], lo: float, hi: float):
    out = []
    for p in points:
        if not L:
            if lo <= p <= hi:
                out.append(p)
            continue
        for k in range(int(np.floor((lo - p) / L)), int(np.ceil((hi - p) / L)) + 1):
            q = p + k * L
            if lo <= q <= hi:
                out.append(q)
    return out


def _shifted_spans(spans, L: Optional[float], lo: float, hi: float):
    out = []
    for a, b in spans:
        ks = range(int(np.floor((lo - b) / L)), int(np.ceil((hi - a) / L)) + 1) if L else [0]
        for k in ks:
            x0, x1 = a + k * (L or 0.0), b + k * (L or 0.0)
            if x1 > lo and x0 < hi:
                out.append((max(x0, lo), min(x1, hi)))
    return out


def _shade_kinds(ax, spans):
    for a, b, kind in spans:
        if kind in KIND_COLOUR:
            ax.axvspan(a, b, color=KIND_COLOUR[kind], lw=0, zorder=0)


def _kind_handles(spans):
    used = [k for k in KIND_COLOUR if any(kind == k for _, _, kind in spans)]
    return [Patch(color=KIND_COLOUR[k], label=KIND_NAME[k]) for k in used]


# ----------------------------------------------------------------------------- 1 time
def _fig_time(a: ResidualAnalysis):
    t, s, R = a.times, a.s, a.residual
    n = len(a.channels)
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.45 * n + 1.4), sharex=True)
    # element shading in time: track positions of the record mapped back through s(t)
    spans_s = _intervals(a.marks, float(s[0]), float(s[-1])) if a.marks.get("elements") else []
    spans_t = [(float(np.interp(x0, s, t)), float(np.interp(x1, s, t)), k) for x0, x1, k in spans_s]
    big = len(t) > 5000
    for j, ax in enumerate(axes):
        _shade_kinds(ax, spans_t)
        ax.plot(t, R[:, j], lw=0.6, color="C0", rasterized=big)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.axhline(a.offset[j], color="C3", lw=0.9, ls="--")
        ax.set_ylabel(f"{LABELS[j]}\nresidual [N]", fontsize=8)
        ax.text(0.995, 0.96, f"NRMSD {a.nrmsd[j]:.3g}, RMS {a.rms[j]:.3g} N, mean {a.offset[j]:+.3g} N",
                transform=ax.transAxes, ha="right", va="top", fontsize=7,
                bbox=dict(facecolor="white", alpha=0.7, lw=0))
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3, lw=0.5)
        ax.set_xlim(t[0], t[-1])
    axes[-1].set_xlabel("time after the trigger [s]")
    if s[-1] > s[0]:
        L = a.track_length
        top = axes[0].secondary_xaxis("top", functions=(lambda x: np.interp(x, t, s),
                                                        lambda y: np.interp(y, s, t)))
        top.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v % L:.4g}"))
        top.set_xlabel("track position s mod L [m] (from the simulated transducer.s)", fontsize=8)
        top.tick_params(labelsize=7)
    handles = [Line2D([], [], color="C0", lw=1, label="measured - simulated"),
               Line2D([], [], color="C3", lw=1, ls="--", label="mean (offset)")] + _kind_handles(spans_t)
    _head(fig, f"Residual per channel over time{_title_tail(a)}", handles, ncol=len(handles))
    return fig


def _head(fig, title: str, handles, ncol: int):
    """Title at the top left, the legend in rows under it, the axes below both."""
    h = fig.get_figheight()
    rows = int(np.ceil(len(handles) / max(ncol, 1)))
    t_in, row_in = 0.35, 0.2
    fig.suptitle(title, fontsize=10, x=0.01, y=1 - 0.08 / h, ha="left", va="top")
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 1 - t_in / h), fontsize=7, ncol=ncol,
               frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 1 - (t_in + rows * row_in + 0.1) / h))


def _title_tail(a: ResidualAnalysis) -> str:
    lay = f", {a.layout_name}" if a.layout_name else ""
    return f" ({len(a.times)} samples, {a.s[-1] - a.s[0]:.3g} m of track{lay}, f = sum H^2 = {np.sum(a.nrmsd ** 2):.3g})"


# ----------------------------------------------------------------------------- 2 fold
def _fig_fold(a: ResidualAnalysis):
    fo, mk = a.fold, a.marks
    lo, hi = float(fo["edges"][0]), float(fo["edges"][-1])
    L = mk.get("length", a.track_length)
    n = len(a.channels)
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.45 * n + 1.6), sharex=True)
    spans = _intervals(mk, lo, hi)
    joints = _shifted(mk.get("joints", []), L, lo, hi)
    motors = _shifted_spans(mk.get("motors", []), L, lo, hi)
    runs = _shifted_spans([(r["s0"], r["s1"]) for r in mk.get("runs", []) if not r["spiral"]], L, lo, hi)
    spirals = _shifted_spans([(r["s0"], r["s1"]) for r in mk.get("runs", []) if r["spiral"]], L, lo, hi)
    c = a.concentration
    st = c.get("stretch", {})
    x = fo["edges"]
    for j, ax in enumerate(axes):
        _shade_kinds(ax, spans)
        for p in joints:
            ax.axvline(p, color="0.45", lw=0.5, ls=":", zorder=1)
        for m0, m1 in motors:
            ax.axvspan(m0, m1, ymin=0.0, ymax=0.07, color=MOTOR_COLOUR, lw=0, zorder=2)
        for r0, r1 in runs:
            ax.axvspan(r0, r1, ymin=0.93, ymax=1.0, color=LEVEL_COLOUR, lw=0, zorder=2)
        for r0, r1 in spirals:
            ax.axvspan(r0, r1, ymin=0.93, ymax=1.0, color="#5b8dd6", lw=0, zorder=2)
        mean = np.append(fo["mean"][:, j], fo["mean"][-1, j])
        rms = np.append(fo["rms"][:, j], fo["rms"][-1, j])
        ax.step(x, rms, where="post", color="0.35", lw=0.7, zorder=3)
        ax.step(x, mean, where="post", color="C0", lw=1.0, zorder=4)
        ax.axhline(0.0, color="k", lw=0.5)
        if j == c.get("channel_index") and st:
            for q0, q1 in _shifted_spans([(st["start"], st["end"])], L if fo["full_lap"] else None, lo, hi):
                ax.axvspan(q0, q1, facecolor="none", edgecolor=WINDOW_COLOUR, lw=1.5, hatch="//", zorder=5)
        ax.set_ylabel(f"{LABELS[j]} [N]", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3, lw=0.5)
        ax.set_xlim(lo, hi)
    axes[-1].set_xlabel("track position s mod L [m]" if fo["full_lap"] else
                        f"track position s [m] (the record covers {lo:.2f}-{hi:.2f} m; read modulo L = {L:.4g} m)")
    handles = [Line2D([], [], color="C0", lw=1.2, label="bin mean"),
               Line2D([], [], color="0.35", lw=0.8, label="bin RMS")] + _kind_handles(spans)
    if joints:
        handles.append(Line2D([], [], color="0.45", lw=0.8, ls=":", label="element joint"))
    if motors:
        handles.append(Patch(color=MOTOR_COLOUR, label="linear motor"))
    if runs:
        handles.append(Patch(color=LEVEL_COLOUR, label="level change"))
    if spirals:
        handles.append(Patch(color="#5b8dd6", label="spiral run"))
    if st:
        handles.append(Patch(facecolor="none", edgecolor=WINDOW_COLOUR, hatch="//",
                             label=f"densest {st['width']:.3g} m window ({st['pattern']})"))
    laps = fo.get("laps", 0.0)
    _head(fig, f"Residual folded over the track position: {len(fo['count'])} bins of {fo['bin_width']:.3g} m, "
               f"{laps:.2f} laps{_title_tail(a)}", handles, ncol=min(len(handles), 5))
    return fig


# ----------------------------------------------------------------------------- 3 orders
def _fig_orders(a: ResidualAnalysis):
    o = a.orders
    f, amp = o["order_per_m"], o["amplitude"]
    n = len(a.channels)
    fig, axes = plt.subplots(n, 1, figsize=(10, 1.45 * n + 1.6), sharex=True)
    lines = o.get("lines", {})
    if len(f) == 0:
        for ax in axes:
            ax.text(0.5, 0.5, "no order spectrum (too few distinct positions)", ha="center", va="center",
                    transform=ax.transAxes)
        fig.suptitle("Order spectrum of the residual: not available", fontsize=10)
        return fig
    tops = [ln["order"] for ln in lines.values() if ln["order"] < o["nyquist"]]
    xmax = min(o["nyquist"], max(12.0, 3.0 * max(tops, default=4.0), 8.0 * o["resolution"]))
    shown = (f > 0) & (f <= xmax)
    lobe = o.get("main_lobe", 2 * o["resolution"])
    for j, ax in enumerate(axes):
        y = amp[shown, j]
        ax.semilogy(f[shown], np.maximum(y, 1e-6), color="C0", lw=0.8)
        ax.axvspan(0, min(2 * lobe, xmax), color="0.9", lw=0, zorder=0)
        for k, (name, ln) in enumerate(lines.items()):
            col = LINE_COLOUR.get(name, f"C{(k + 4) % 10}")
            ax.axvline(ln["order"], color=col, lw=1.0, ls="--" if ln["resolved"] else ":", zorder=3)
            if ln["resolved"] and np.isfinite(ln["line_snr"][j]):
                snr = ln["line_snr"][j]
                ax.plot(ln["peak_order"][j], ln["amplitude"][j], "o", ms=4, color=col,
                        mfc=col if snr >= LINE_SNR_THRESHOLD else "white", zorder=4)
                if snr >= LINE_SNR_THRESHOLD:
                    ax.annotate(f"{name}: {ln['amplitude'][j]:.3g} N, SNR {snr:.0f}",
                                (ln["peak_order"][j], ln["amplitude"][j]), xytext=(4, 2),
                                textcoords="offset points", fontsize=7, color=col)
        ax.set_ylabel(f"{LABELS[j]} [N]", fontsize=8)
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3, lw=0.5, which="both")
        ax.set_xlim(0, xmax)
    axes[-1].set_xlabel("order [cycles per metre of track]")
    handles = [Line2D([], [], color="C0", lw=1, label="residual amplitude (Hann, mean and trend removed)"),
               Patch(color="0.9", label="fewer than 4 cycles in the record: lines not resolved")]
    for k, (name, ln) in enumerate(lines.items()):
        col = LINE_COLOUR.get(name, f"C{(k + 4) % 10}")
        handles.append(Line2D([], [], color=col, lw=1, ls="--" if ln["resolved"] else ":",
                              label=f"{name} {ln['order']:.3g}/m" + ("" if ln["resolved"] else " (not resolved)")))
    handles.append(Line2D([], [], color="k", marker="o", lw=0, ms=4,
                          label=f"line SNR >= {LINE_SNR_THRESHOLD:g} (filled)"))
    _head(fig, f"Order spectrum of the residual over distance: {o['record_length']:.3g} m of record, "
               f"resolution {o['resolution']:.3g} cycles/m (zero-padded, bin spacing {o['bin_spacing']:.3g}), "
               "amplitude in N", handles, ncol=3)
    return fig


# ----------------------------------------------------------------------------- 4 signals
def _fig_signals(a: ResidualAnalysis):
    names = [k for k, st in a.signals.items() if not st["constant"]]
    n = len(a.channels)
    j0 = a.concentration.get("channel_index", 0)
    nb = max(len(names), 1)
    fig = plt.figure(figsize=(max(10, 2.6 * nb), 8.5))
    gs = fig.add_gridspec(2, max(nb, 2), height_ratios=[1.25, 1.0], hspace=0.55, wspace=0.45)
    if not names:
        ax = fig.add_subplot(gs[0, :])
        ax.text(0.5, 0.5, "no varying model signal (give a layout or model_signals)", ha="center", va="center")
        ax.axis("off")
        return fig
    half = max(nb, 2) // 2
    corr = np.array([a.signals[k]["corr"] for k in names]).T
    eta = np.array([a.signals[k]["eta2"] for k in names]).T
    for pos, data, cmap, vmin, title in ((gs[0, :half], corr, "RdBu_r", -1.0, "correlation with the residual"),
                                         (gs[0, half:], eta, "viridis", 0.0, "eta^2: variance share explained by "
                                                                           "binned mean")):
        ax = fig.add_subplot(pos)
        im = ax.imshow(data, cmap=cmap, vmin=vmin, vmax=1.0, aspect="auto")
        ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
        ax.set_yticks(range(n), LABELS if vmin < 0 else [""] * n, fontsize=8)
        for i in range(n):
            for k in range(len(names)):
                v = data[i, k]
                ax.text(k, i, f"{v:.2f}", ha="center", va="center", fontsize=7,
                        color="white" if (abs(v) > 0.6 if vmin < 0 else v < 0.5) else "black")
        ax.set_title(title, fontsize=9)
        cb = fig.colorbar(im, ax=ax, fraction=0.05, pad=0.02)
        cb.ax.tick_params(labelsize=7)
    units = {"curvature": "1/m", "vertical_curvature": "1/m", "incline": "rad", "motor": "0/1", "v": "m/s",
             "v_joint": "m/s"}
    for k, name in enumerate(names):
        ax = fig.add_subplot(gs[1, k])
        b = a.signals[name]["bins"]
        ax.errorbar(b["centre"], b["mean"][:, j0], yerr=b["sem"][:, j0], fmt="o-", ms=3, lw=0.8, capsize=2)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel(f"{name} [{units.get(name, '-')}]", fontsize=8)
        if k == 0:
            ax.set_ylabel(f"{LABELS[j0]} residual [N]\n(bin mean +- s.e.)", fontsize=8)
        ax.set_title(f"eta^2 {a.signals[name]['eta2'][j0]:.2f}, r {a.signals[name]['corr'][j0]:+.2f}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3, lw=0.5)
    fig.suptitle(f"Residual against the model signals (bottom: {a.channels[j0]}, the channel with the largest "
                 f"share of sum H^2)", fontsize=10, x=0.02, ha="left")
    return fig


# ----------------------------------------------------------------------------- 5 forces
def _fig_forces(a: ResidualAnalysis, measured, simulated):
    M, S = np.asarray(measured, float), np.asarray(simulated, float)
    n = len(a.channels)
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.45 * n + 1.2), sharex=True)
    big = len(a.times) > 5000
    for j, ax in enumerate(axes):
        ax.plot(a.times, M[:, j], color="k", lw=0.7, label="measured", rasterized=big)
        ax.plot(a.times, S[:, j], color="C3", lw=0.7, ls="--", label="simulated", rasterized=big)
        ax.set_ylabel(f"{LABELS[j]} [N]", fontsize=8)
        ax.text(0.995, 0.96, f"NRMSD {a.nrmsd[j]:.3g}", transform=ax.transAxes, ha="right", va="top", fontsize=7,
                bbox=dict(facecolor="white", alpha=0.7, lw=0))
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3, lw=0.5)
        ax.set_xlim(a.times[0], a.times[-1])
    axes[-1].set_xlabel("time after the trigger [s]")
    handles = [Line2D([], [], color="k", lw=1, label="measured"),
               Line2D([], [], color="C3", lw=1, ls="--", label="simulated")]
    _head(fig, f"Measured and simulated forces{_title_tail(a)}", handles, ncol=2)
    return fig


def residual_figures(analysis: ResidualAnalysis, out_dir, measured=None, simulated=None,
                     formats: Sequence[str] = ("png", "svg"), prefix: str = "residual") -> list:
    """Draw the figures of `analysis` into out_dir as PNG and SVG; returns the
    written paths (PNG first for each figure)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    paths += _save(_fig_time(analysis), out, f"{prefix}_time", formats)
    paths += _save(_fig_fold(analysis), out, f"{prefix}_fold", formats)
    paths += _save(_fig_orders(analysis), out, f"{prefix}_orders", formats)
    paths += _save(_fig_signals(analysis), out, f"{prefix}_signals", formats)
    if measured is not None and simulated is not None:
        n = analysis.residual.shape[0]
        M, S = as_matrix("measured", measured, n), as_matrix("simulated", simulated, n)
        paths += _save(_fig_forces(analysis, M, S), out, f"{prefix}_forces", formats)
    return paths
