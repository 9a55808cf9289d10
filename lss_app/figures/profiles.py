"""Objective profiles drawn (identification.pipeline.profile): f along each
variable, the noise floor shaded, the truth marked where known."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from identification.pipeline.profile import Profile
from lss_fmu.design import symbol
from .save import save_figure


def plot_profiles(profiles: list[Profile], floor: Optional[np.ndarray], path: Path, title: str,
                  truth: Optional[dict] = None) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = len(profiles)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.4), sharey=True, squeeze=False)
    for ax, p in zip(axes[0], profiles):
        ax.plot(p.grid, p.f, "o-", ms=3, label="re-optimised" if p.reoptimised else "others fixed")
        if floor is not None and len(floor):
            ax.axhspan(0, float(np.max(floor)), color="0.85", label="noise floor")
        if truth and p.name in truth:
            ax.axvline(truth[p.name], color="k", ls=":", lw=1, label="truth")
        ax.set_xlabel(symbol(p.name))
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("objective f")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)
