"""Saving a figure the way every figure of the application is kept."""
from __future__ import annotations

from pathlib import Path


def save_figure(fig, path, dpi: int = 100, formats=("png", "svg")) -> Path:
    """`path` with each suffix of `formats` (PNG for reading, SVG for print);
    the figure is closed; returns the first (the PNG)."""
    import matplotlib.pyplot as plt  # the caller chose the backend
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for ext in formats:
        fig.savefig(path.with_suffix("." + ext), dpi=dpi)
    plt.close(fig)
    return path.with_suffix("." + formats[0])
