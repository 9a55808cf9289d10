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
                   labels: tuple = ("initial", "optimum"), tare=None, noise=None) -> Path:
    """The measured forces and the simulations as the objective compares them:
    with `tare` (N per channel) each simulation is shifted by the zero error
    the objective takes out (the mean residual, clipped to the tolerance);
    with `noise` (the sensor's sigma per channel) a +-2 sigma band about the
    record, and each channel's RMSD of the last simulation over sigma (about 1
    where only the noise is left) in its label."""
    def seen(sim):
        if sim is None or tare is None:
            return sim
        return sim + np.clip((measured - sim).mean(axis=0), -np.asarray(tare), np.asarray(tare))

    initial, optimum = seen(initial), seen(optimum)
    last = optimum if optimum is not None else initial
    fig, axes = plt.subplots(len(FORCE_CHANNELS), 1, figsize=(11, 13), sharex=True)
    for j, ax in enumerate(axes):
        if noise is not None:
            ax.fill_between(times, measured[:, j] - 2 * noise[j], measured[:, j] + 2 * noise[j], color="0.85",
                            lw=0, label="measured +- 2 sigma")
        ax.plot(times, measured[:, j], color="k", lw=0.8, label="measured")
        if initial is not None:
            ax.plot(times, initial[:, j], color="tab:blue", lw=0.7, ls=":", label=labels[0])
        if optimum is not None:
            ax.plot(times, optimum[:, j], color="tab:red", lw=0.7, ls="--", label=labels[1])
        ylabel = f"{LABELS[j]}, N"
        if last is not None:
            rmsd = float(np.sqrt(np.mean((measured[:, j] - last[:, j]) ** 2)))
            ylabel += f"\nRMSD {rmsd:.3g} N" + (f" = {rmsd / noise[j]:.2f} sigma" if noise is not None else "")
        ax.set_ylabel(ylabel, fontsize=7)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncol=4)
    axes[-1].set_xlabel("time after the trigger, s")
    if tare is not None:
        title += " (simulations shifted by the zero error within the transducer's tolerance, as the objective sees them)"
    fig.suptitle(title, fontsize=10)
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
