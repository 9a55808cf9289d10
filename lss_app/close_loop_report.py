"""The close-loop report: Markdown with figures, next to result.json.

Per round: the verdict, the attribution ranking (share of f each effect
explains beyond the base parameters), the residual analysis figures, and for
an extension the identified effect values, f and NRMSD per channel before and
after, with overlays of measured, old model and extended model.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from identification.catalogue import CATALOGUE  # noqa: E402
from identification.close_loop import CONFIRM, SHARE_MIN  # noqa: E402
from lss_fmu.design import LABELS  # noqa: E402

from .figures.identification import forces_overlay, nrmsd_bars  # noqa: E402


def ranking_figure(rnd, path: Path, threshold: float) -> Path:
    rk = rnd.attribution.ranking
    fig, ax = plt.subplots(figsize=(8, 0.45 * max(len(rk), 3) + 1.2))
    names = [f"{r.effect} ({r.label})" for r in rk][::-1]
    y = np.arange(len(rk))
    ax.barh(y + 0.2, [100 * r.share for r in rk][::-1], 0.4, color="tab:blue",
            label="linear fit, beyond the base parameters")
    ax.barh(y - 0.2, [100 * (r.share_fit or 0.0) for r in rk][::-1], 0.4, color="tab:orange",
            label="fitted through the FMU (top candidates)")
    ax.set_yticks(y, names, fontsize=8)
    ax.axvline(100 * threshold, color="tab:red", ls="--", lw=1,
               label=f"candidate threshold {100 * threshold:.0f}% (either estimate)")
    ax.set_xlabel("share of the objective f explained, %")
    ax.set_title(f"Round {rnd.number}: attribution of the residual (f = {rnd.f_base:.4g})")
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    for ext in ("png", "svg"):
        fig.savefig(path.with_suffix("." + ext), dpi=100)
    plt.close(fig)
    return path.with_suffix(".png")


def write_report(res, out: Path) -> Path:
    out = Path(out)
    p = res.problem
    lines = [f"# Closing the loop: {p.name}, model {p.model}", "",
             f"Layout `{p.layout}`, {len(p.times)} samples ({p.times[-1]:.2f} s), base design "
             f"{', '.join(p.free)}. {res.seconds:.0f} s in all.", "",
             f"**Verdict:** {res.verdict}.", ""]
    if res.found:
        lines += [f"Effects found, in turn: {', '.join(res.found)}.", ""]
    for rnd in res.rounds:
        lines += [f"## Round {rnd.number}", "", rnd.verdict + ".", ""]
        fig = ranking_figure(rnd, out / f"round{rnd.number}_attribution", SHARE_MIN)
        lines += ["| effect | best hypothesis | share of f, linear (beyond base) | linear, alone | "
                  "fitted through the FMU |", "|---|---|---|---|---|"]
        for r in rnd.attribution.ranking:
            fit = "-" if r.share_fit is None else f"{100 * r.share_fit:.1f}%"
            lines.append(f"| {r.effect}: {CATALOGUE[r.effect].title} | {r.label} | {100 * r.share:.1f}% | "
                         f"{100 * r.share_alone:.1f}% | {fit} |")
        lines += ["", f"The base parameters alone, refitted linearly, would bring f from "
                      f"{rnd.attribution.f_base:.4g} to {rnd.attribution.f_base_refit:.4g}. An effect is "
                      f"a candidate when it explains at least {100 * SHARE_MIN:.0f}% of f, linearly beyond the base "
                      f"parameters or fitted through the FMU with the base held, and significant when the "
                      f"extended identification lowers f by at least {100 * CONFIRM:.0f}%.", "",
                  f"![attribution]({fig.name})", ""]
        if rnd.attribution.failed:
            lines += [f"Probe runs that failed: {len(rnd.attribution.failed)} (see result.json).", ""]
        lines += _residual_section(rnd, out)
        if rnd.location:
            lines += ["Where the residual concentrates: " + ", ".join(
                f"{k} = {v:.3g}" if isinstance(v, float) else f"{k} = {v}" for k, v in rnd.location.items()), ""]
        if rnd.effect is not None:
            lines += _extension_section(rnd, p, out)
    path = out / "report.md"
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)
    return path


def _residual_section(rnd, out: Path) -> list:
    ra = rnd.residual
    if ra is None:
        return []
    lines = []
    try:
        from identification.residual import describe

        from .figures.residual import residual_figures
        figs = residual_figures(ra, out / f"round{rnd.number}_residual")
        lines += ["### Residual", "", describe(ra), ""]
        lines += [f"![{f.stem}]({f.relative_to(out)})" for f in figs if f.suffix == ".png"]
        lines.append("")
    except Exception as exc:  # the report goes on without the figures
        lines += [f"(residual figures failed: {exc})", ""]
    return lines


def _extension_section(rnd, base_problem, out: Path) -> list:
    pe = rnd.problem_extended
    lines = ["### Extended model", "",
             f"{CATALOGUE[rnd.effect].title} switched on; identified values:", "",
             "| parameter | value |", "|---|---|"]
    lines += [f"| {k} | {v:.5g} |" for k, v in rnd.identified.items()]
    lines += ["", f"Objective f: {rnd.f_base:.4g} (base) -> {rnd.f_extended:.4g} (extended), "
                  f"{100 * (1 - rnd.f_extended / rnd.f_base):.0f}% lower.", "",
              "| channel | NRMSD base | NRMSD extended |", "|---|---|---|"]
    for lab, a, b in zip(LABELS, rnd.H_base, rnd.H_extended):
        lines.append(f"| {lab} | {100 * a:.2f}% | {100 * b:.2f}% |")
    lines.append("")
    try:
        old = _sim_without_effect(rnd)
        new = pe.simulate(rnd.x_extended)
        title = f"round {rnd.number}: {rnd.effect}"
        f1 = forces_overlay(pe.times, pe.samples, old, new, out / f"round{rnd.number}_overlay", title,
                            labels=("old model", "extended model"))
        f2 = nrmsd_bars(rnd.H_base, rnd.H_extended, out / f"round{rnd.number}_nrmsd", title,
                        labels=("old model", "extended model"))
        lines += [f"![overlay]({f1.name})", "", f"![nrmsd]({f2.name})", ""]
    except Exception as exc:
        lines += [f"(overlay figures failed: {exc})", ""]
    return lines


def _sim_without_effect(rnd) -> np.ndarray:
    """The old model as the round started: the base problem at its optimum."""
    return rnd.base_problem.simulate(rnd.x_base)
