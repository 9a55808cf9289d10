"""Figures of one identification, as in the paper: measured / initial /
optimum forces (Fig. 8, 9), the iteration history (Fig. 10) and the NRMSD
per channel before and after (Fig. 11)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from lss_fmu.design import LABELS  # noqa: E402
from lss_fmu.variables import FORCE_CHANNELS  # noqa: E402
from .save import save_figure  # noqa: E402


def forces_overlay(times, measured, initial, optimum, path: Path, title: str,
                   labels: tuple = ("initial", "optimum")) -> Path:
    fig, axes = plt.subplots(len(FORCE_CHANNELS), 1, figsize=(11, 13), sharex=True)
    for j, ax in enumerate(axes):
        ax.plot(times, measured[:, j], color="k", lw=0.8, label="measured")
        if initial is not None:
            ax.plot(times, initial[:, j], color="tab:blue", lw=0.7, ls=":", label=labels[0])
        if optimum is not None:
            ax.plot(times, optimum[:, j], color="tab:red", lw=0.7, ls="--", label=labels[1])
        ax.set_ylabel(f"{LABELS[j]}, N", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncol=3)
    axes[-1].set_xlabel("time after the trigger, s")
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)


def history(f_per_eval, path: Path, title: str, series: dict | None = None) -> Path:
    """Objective of every evaluation and the best so far (log scale); more
    runs (e.g. one per contact model) can be passed as `series`."""
    fig, ax = plt.subplots(figsize=(8, 4.5))
    runs = series or {"": f_per_eval}
    for name, f in runs.items():
        f = np.asarray(f, float)
        f = np.where(np.isfinite(f), f, np.nan)
        if not series:
            ax.plot(np.arange(len(f)), f, ".", ms=2, color="0.6", label="evaluations")
        ax.plot(np.arange(len(f)), np.fmin.accumulate(np.nan_to_num(f, nan=np.inf)), lw=1.5,
                label=f"best so far {name}".strip())
    ax.set_yscale("log")
    ax.set_xlabel("evaluation")
    ax.set_ylabel("objective f = sum H_j^2")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    return save_figure(fig, path)


def nrmsd_bars(H0, H, path: Path, title: str, labels: tuple = ("initial", "final")) -> Path:
    fig, ax = plt.subplots(figsize=(8, 4))
    x = np.arange(len(LABELS))
    ax.bar(x - 0.2, 100 * np.asarray(H0), 0.4, label=labels[0])
    ax.bar(x + 0.2, 100 * np.asarray(H), 0.4, label=labels[1])
    ax.set_xticks(x, LABELS, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("NRMSD H_j, %")
    ax.legend()
    ax.grid(alpha=0.3, axis="y")
    ax.set_title(title)
    fig.tight_layout()
    return save_figure(fig, path)
