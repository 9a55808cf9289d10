"""A figure of one measurement: the seven forces over the logged lap, with
the track position on the top axis and the curves shaded (docs/measurements.md)."""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Union

import numpy as np

from lss_fmu.measurement import Measurement
from lss_fmu.variables import FORCE_CHANNELS


def plot_measurement(m: Measurement, path: Optional[Union[str, Path]] = None, title: Optional[str] = None,
                     formats=("png", "svg"), shade_curves: bool = True):
    """The 7 force channels of a measurement over the logged lap (time below,
    track position s on the top axis: s_M + v_nominal t, modulo the track
    length), horizontal curves shaded grey and vertical curves orange, as the
    track drawing gives them. Saves path.<format> for each format when path
    is given; returns the figure."""
    import matplotlib
    if path is not None:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from lss_fmu.layout_format import CURVE, SPIRAL, VCURVE
    t = m.time
    v = float(m.meta["speed_nominal"])
    s_M = float(m.meta["trigger_point"])
    spans = []
    L = None
    if shade_curves:
        try:
            tr = m.track
            L = tr.length
            bounds = tr.boundaries()
            colours = {CURVE: "0.88", SPIRAL: "#cfe0f5", VCURVE: "#fbe3c8"}
            # element intervals in time, over the logged distance (unwrapped)
            dist = v * t[-1]
            for lap in range(int(np.floor(s_M / L)) - 1, int(np.ceil((s_M + dist) / L)) + 1):
                for k, kind in enumerate(tr.kind):
                    if kind in colours:
                        a = (bounds[k] + lap * L - s_M) / v
                        b = (bounds[k + 1] + lap * L - s_M) / v
                        if b > 0 and a < t[-1]:
                            spans.append((max(a, 0.0), min(b, t[-1]), colours[kind]))
        except Exception:  # a figure without shading rather than none
            spans = []
    n = len(FORCE_CHANNELS)
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.45 * n + 1.2), sharex=True)
    for ax, c in zip(axes, FORCE_CHANNELS):
        for a, b, col in spans:
            ax.axvspan(a, b, color=col, lw=0, zorder=0)
        ax.plot(t, m.samples[c].to_numpy(), lw=0.6, color="C0", rasterized=True)  # small SVGs
        ax.set_ylabel(c.replace("transducer.", "").replace(".", "\n", 1) + " [N]", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3, lw=0.5)
        ax.set_xlim(t[0], t[-1])
    axes[-1].set_xlabel("time since trigger [s]")
    top = axes[0].secondary_xaxis("top", functions=(lambda x: s_M + v * x, lambda s: (s - s_M) / v))
    if L:
        # ticks at round track positions, lap by lap (the position wraps at L)
        u0, u1 = s_M, s_M + v * t[-1]
        step = next(st for st in (1, 2, 5, 10, 20, 25, 50, 100, 200, 250, 500, 1000)
                    if (u1 - u0) / st <= 12)
        ticks = [lap * L + k * step for lap in range(int(np.floor(u0 / L)), int(np.floor(u1 / L)) + 1)
                 for k in range(int(np.ceil(L / step)))
                 if u0 <= lap * L + k * step <= u1 and (k * step < L - 0.4 * step or k == 0)]
        top.set_xticks(ticks)
        top.xaxis.set_major_formatter(FuncFormatter(lambda s, _: f"{s % L:.0f}"))
    top.set_xlabel(f"track position s [m] (s_M = {s_M:g} m, at the nominal {v:g} m/s)", fontsize=9)
    top.tick_params(labelsize=8)
    fig.suptitle(title or f"{m.id}: {m.meta['layout']}, {v:g} m/s, d = {m.meta['pretension_nominal'] * 1e3:g} mm, "
                 f"{m.n_samples} samples at {m.sample_rate:g} Hz", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.985))
    if spans:
        from matplotlib.patches import Patch
        names = {"0.88": "horizontal curve", "#cfe0f5": "spiral", "#fbe3c8": "vertical curve"}
        used = [c for c in names if any(col == c for _, _, col in spans)]
        fig.legend(handles=[Patch(color=c, label=names[c]) for c in used], loc="upper right",
                   fontsize=7, ncol=len(used), frameon=False)
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        for fmt in formats:
            fig.savefig(path.with_suffix(f".{fmt}"), dpi=110)
    return fig
