"""Drawings of a layout in the manner of the paper's Figure 4.

Top view: the track as two parallel lines (track width), level changes shaded
and closed by lines across the track, spirals likewise in another colour,
arrows in the driving direction, distance marks from s = 0 and the linear
motors. Below it, the elevation profile over arc length.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lss_fmu.track_geometry import Track

TRACK_WIDTH = 0.6  # m, drawn distance between the two track lines
LEVEL_COLOUR, SPIRAL_COLOUR, MOTOR_COLOUR = "#f4a259", "#5b8dd6", "#2a9d4b"


def _mark_step(length: float) -> float:
    for step in (5, 10, 20, 25, 50, 100):
        if length / step <= 20:
            return step
    return 200


def _edges(track: Track, s: np.ndarray):
    c, R, _, _ = track.frame(s)
    n = R[:, :, 1]
    half = 0.5 * TRACK_WIDTH
    return c, n, c + half * n, c - half * n


def plot_layout(track: Track, title: str | None = None):
    """A matplotlib Figure with the top view and the elevation profile."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    L = track.length
    s = np.unique(np.concatenate([np.linspace(0, L, max(400, int(L / 0.05)) + 1), track.boundaries()]))
    c, n, left, right = _edges(track, s)
    x0, x1, y0, y1 = c[:, 0].min(), c[:, 0].max(), c[:, 1].min(), c[:, 1].max()
    span = max(x1 - x0, y1 - y0, 1.0)
    width_in = 11.0
    top_h = min(max(width_in * (y1 - y0 + 0.16 * span) / (x1 - x0 + 0.16 * span), 2.6), 8.0)
    fig = plt.figure(figsize=(width_in, top_h + 2.6))
    gs = fig.add_gridspec(2, 1, height_ratios=[top_h, 2.0], hspace=0.35)
    ax, az = fig.add_subplot(gs[0]), fig.add_subplot(gs[1])

    # orientation: the outside of the loop is to the right of a counter-clockwise loop
    area = 0.5 * np.sum(c[:-1, 0] * c[1:, 1] - c[1:, 0] * c[:-1, 1])
    out_sign = -1.0 if area > 0 else 1.0
    runs = track.inclined_runs()

    # shaded level changes and spirals, closed by lines across the track
    for r in runs:
        colour = SPIRAL_COLOUR if r.spiral else LEVEL_COLOUR
        sr = np.linspace(r.s0, r.s1, max(20, int((r.s1 - r.s0) / 0.05)))
        _, _, lr, rr = _edges(track, sr)
        poly = np.vstack([lr[:, :2], rr[::-1, :2]])
        ax.fill(poly[:, 0], poly[:, 1], color=colour, alpha=0.55, lw=0, zorder=1)
        for k in (0, -1):
            ax.plot([lr[k, 0], rr[k, 0]], [lr[k, 1], rr[k, 1]], color="k", lw=1.0, zorder=3)
    ax.plot(left[:, 0], left[:, 1], color="k", lw=0.8, zorder=2)
    ax.plot(right[:, 0], right[:, 1], color="k", lw=0.8, zorder=2)

    # driving direction
    n_arrows = 10 if L > 100 else 6
    for sa in (np.arange(n_arrows) + 0.25) * L / n_arrows:
        ca, Ra, _, _ = track.frame([sa])
        t = Ra[0, :, 0]
        d = 0.025 * span * t[:2] / max(np.hypot(t[0], t[1]), 1e-9)
        ax.annotate("", xy=(ca[0, 0] + d[0], ca[0, 1] + d[1]), xytext=(ca[0, 0] - d[0], ca[0, 1] - d[1]),
                    arrowprops=dict(arrowstyle="-|>", color="#c0392b", lw=1.4), zorder=5)

    # distance marks from s = 0, outside the loop
    step = _mark_step(L)
    off = 0.035 * span
    for sm in np.arange(0.0, L - 0.25 * step, step):
        cm, nm, lm, rm = (a[0] for a in _edges(track, [sm]))
        o = out_sign * nm
        edge = cm + o * 0.5 * TRACK_WIDTH
        tick = cm + o * (0.5 * TRACK_WIDTH + 0.4 * off)
        ax.plot([edge[0], tick[0]], [edge[1], tick[1]], color="0.3", lw=0.8, zorder=3)
        lab = cm + o * (0.5 * TRACK_WIDTH + off)
        ax.text(lab[0], lab[1], f"{sm:g}", ha="center", va="center", fontsize=7, color="0.2", zorder=6)
    ax.plot(*c[0, :2], marker="o", color="k", ms=5, zorder=6)

    # linear motors
    for m0, m1 in track.motors:
        sm = np.linspace(m0, m1, 5)
        cm = track.position(sm)
        ax.plot(cm[:, 0], cm[:, 1], color=MOTOR_COLOUR, lw=5, solid_capstyle="butt", zorder=4)
        mid = track.position([0.5 * (m0 + m1)])[0]
        ax.plot(mid[0], mid[1], "s", color=MOTOR_COLOUR, ms=4, zorder=4)

    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    handles = [Patch(color=LEVEL_COLOUR, alpha=0.55, label="level change"),
               Line2D([], [], color=MOTOR_COLOUR, lw=5, label="linear motor"),
               Line2D([], [], color="#c0392b", marker=">", lw=0, label="driving direction"),
               Line2D([], [], color="k", marker="o", lw=0, label="s = 0 (distance marks in m)")]
    if any(r.spiral for r in runs):
        handles.insert(1, Patch(color=SPIRAL_COLOUR, alpha=0.55, label="spiral"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8, frameon=False)
    ax.set_aspect("equal")
    pad = 0.08 * span
    ax.set_xlim(x0 - pad, x1 + pad)
    ax.set_ylim(y0 - pad, y1 + pad)
    ax.set_xlabel("x, m")
    ax.set_ylabel("y, m")
    n_lc = sum(not r.spiral for r in runs)
    n_sp = len(runs) - n_lc
    ax.set_title(title or (f"{track.spec.name}: {L:.2f} m, {track.n_carts} carts, {len(track.motors)} motors, "
                           f"{n_lc} level change{'s' if n_lc != 1 else ''}"
                           + (f" + {n_sp} spiral{'s' if n_sp != 1 else ''}" if n_sp else "")
                           + f", wheel {track.spec.wheel}, coupling {track.spec.coupling}"), fontsize=10)

    # elevation profile
    z = c[:, 2]
    for r in runs:
        az.axvspan(r.s0, min(r.s1, L), color=SPIRAL_COLOUR if r.spiral else LEVEL_COLOUR, alpha=0.35, lw=0)
        if r.s1 > L:
            az.axvspan(0, r.s1 - L, color=SPIRAL_COLOUR if r.spiral else LEVEL_COLOUR, alpha=0.35, lw=0)
    az.plot(s, z, color="k", lw=1.2)
    zr = max(z.max() - z.min(), 0.5)
    zb = z.min() - 0.12 * zr
    for m0, m1 in track.motors:
        az.plot([m0, m1], [zb, zb], color=MOTOR_COLOUR, lw=6, solid_capstyle="butt")
    az.set_xlim(0, L)
    az.set_ylim(zb - 0.1 * zr, z.max() + 0.15 * zr)
    az.set_xticks(np.arange(0, L + 1e-9, step))
    az.set_xlabel("arc length s, m")
    az.set_ylabel("height z, m")
    az.grid(alpha=0.3)
    return fig


def save_layout_plot(track: Track, out_dir: Path, formats=("png", "svg"), stem: str | None = None) -> list:
    """Draw and save as out_dir/<name>.<fmt>; returns the written paths."""
    import matplotlib.pyplot as plt
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fig = plot_layout(track)
    paths = []
    for fmt in formats:
        path = out_dir / f"{stem or track.spec.name}.{fmt}"
        meta = {"Date": None} if fmt == "svg" else {}
        fig.savefig(path, dpi=150, bbox_inches="tight", metadata=meta)
        paths.append(path)
    plt.close(fig)
    return paths
