"""The campaign report's figures of single identifications (the paper's
Fig. 8-11): for each contact law, one measurement shown whole (measured
forces against the simulations at the start and at the optimum, as the
objective compares them, and the objective's history), and the NRMSD per
channel before and after over all measurements of each law.

The overlays simulate (two runs per law shown, on the window the result is
for, from the records the result names); everything else is read from the
result files. A measurement that cannot be simulated any more (its records
moved) is said in the report, not raised.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from lss_fmu.variables import FORCE_CHANNELS

log = logging.getLogger(__name__)


def shown(results: list[dict], wanted: Optional[Sequence[str]] = None) -> list[dict]:
    """The results whose figures are drawn: of each law, the measurements
    named in `wanted` (sorter names, as the result files give them), or by default the one at the
    median of that law's f (the lower middle one for an even count)."""
    out = []
    for model in sorted({r["model"] for r in results}):
        mine = sorted((r for r in results if r["model"] == model), key=lambda r: (r["f"], r.get("sorter", "")))
        if wanted:
            out += [r for r in mine if r.get("sorter", r.get("measurement")) in wanted]
        elif mine:
            out.append(mine[(len(mine) - 1) // 2])
    return out


def _vector(values: dict, names: Sequence[str], where: str) -> np.ndarray:
    missing = [n for n in names if n not in values]
    if missing:
        raise ValueError(f"{where}: no value for {missing[0]}")
    return np.array([float(values[n]) for n in names])


def simulate_result(result: dict) -> tuple:
    """(problem of the first record on the result's window, simulation at x0,
    simulation at x): the problem rebuilt from the records and settings the
    result names."""
    from identification.pipeline.driver import build_problem
    from identification.pipeline.settings import settings_from
    from identification.pipeline.windowing import truncated
    from lss_fmu.measurement import load_measurement

    records = [load_measurement(p) for p in result["records"]]
    problem = build_problem(records, result["model"], settings_from(result["settings"], where=result["_file"]))
    try:
        window = float(result.get("window_s") or problem.times[-1])
        q = truncated(problem, window) if window < float(problem.times[-1]) - 1e-9 else problem
        x0 = _vector(result["x0"], q.free, result["_file"])
        x = _vector(result["x"], q.free, result["_file"])
        if hasattr(q, "parts"):
            part, x0, x = q.parts[0], q.part_x(0, x0), q.part_x(0, x)
        else:
            part = q
        return part, part.simulate(x0), part.simulate(x)
    finally:
        for p in getattr(problem, "parts", [problem]):
            p.sim.close()


def single_figures(result: dict, out: Path) -> tuple[list[str], Optional[str]]:
    """Fig. 8-10 of one result into `out`: (figure file names, or a note why not)."""
    from .figures.identification import forces_overlay, history

    name = f"{result.get('sorter', 'record')}_{result['model']}"
    title = f"{result.get('sorter', '')}, model {result['model']}"
    figs = []
    try:
        q, initial, optimum = simulate_result(result)
    except Exception as exc:   # the figures of a result whose records cannot be simulated: said, not raised
        log.warning("%s: cannot simulate for the figures: %s", result["_file"], exc)
        return figs, f"{title}: no force overlay ({str(exc).splitlines()[0]})"
    forces_overlay(q.times, q.samples, initial, optimum, out / f"forces_{name}", f"{title}: f {result['f']:.4g}",
                   tare=q.tare, noise=q.noise)
    figs.append(f"forces_{name}.png")
    if result.get("history_f"):
        history(result["history_f"], out / f"history_{name}", title)
        figs.append(f"history_{name}.png")
    return figs, None


def nrmsd_by_law(results: list[dict], out: Path) -> Optional[str]:
    """Fig. 11 over the campaign: per law, the median over its measurements of
    each channel's NRMSD at the start and at the optimum."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lss_fmu.design import LABELS

    from .figures.save import save_figure

    laws = sorted({r["model"] for r in results if r.get("nrmsd") and r.get("nrmsd0")})
    if not laws:
        return None
    fig, axes = plt.subplots(len(laws), 1, figsize=(8, 2.6 * len(laws)), squeeze=False, sharex=True)
    x = np.arange(len(FORCE_CHANNELS))
    for ax, law in zip(axes[:, 0], laws):
        mine = [r for r in results if r["model"] == law and r.get("nrmsd") and r.get("nrmsd0")]
        h0 = np.median([[r["nrmsd0"][c] for c in FORCE_CHANNELS] for r in mine], axis=0)
        h = np.median([[r["nrmsd"][c] for c in FORCE_CHANNELS] for r in mine], axis=0)
        ax.bar(x - 0.2, 100 * h0, 0.4, label="start")
        ax.bar(x + 0.2, 100 * h, 0.4, label="optimum")
        ax.set_ylabel("NRMSD, %")
        ax.set_title(f"{law}: median over {len(mine)} measurements", fontsize=9)
        ax.grid(alpha=0.3, axis="y")
        ax.legend(fontsize=8)
    axes[-1, 0].set_xticks(x, LABELS, rotation=30, ha="right", fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "nrmsd_by_law")
    return "nrmsd_by_law.png"
