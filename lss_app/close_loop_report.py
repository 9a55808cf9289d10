"""The close-loop report: Markdown with figures, next to result.json.

Per round: the verdict and the evidence behind it (identification.loop.evidence:
the noise per channel, the likelihood-ratio test with its statistic and
p-values, BIC, the held-out gain, the disturbances outside the catalogue,
the candidates dropped and why), the attribution ranking (share of f each
effect explains beyond the base parameters: it orders the candidates, it
does not decide), the residual analysis figures, and for an extension the
identified effect values, f and NRMSD per channel before and after, with
overlays of measured, old model and extended model.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from identification.loop.catalogue import CATALOGUE  # noqa: E402
from identification.objective.noise import ALPHA, EXCESS_MIN  # noqa: E402
from lss_fmu.variables import FORCE_CHANNELS  # noqa: E402
from lss_fmu.design import LABELS  # noqa: E402

from .figures.identification import forces_overlay, nrmsd_bars  # noqa: E402
from .figures.save import save_figure  # noqa: E402


def ranking_figure(rnd, path: Path, threshold: float = None) -> Path:
    rk = rnd.attribution.ranking
    fig, ax = plt.subplots(figsize=(8, 0.45 * max(len(rk), 3) + 1.2))
    names = [f"{r.effect} ({r.label})" for r in rk][::-1]
    y = np.arange(len(rk))
    ax.barh(y + 0.2, [100 * r.share for r in rk][::-1], 0.4, color="tab:blue",
            label="linear fit, beyond the base parameters")
    ax.barh(y - 0.2, [100 * (r.share_fit or 0.0) for r in rk][::-1], 0.4, color="tab:orange",
            label="fitted through the FMU (top candidates)")
    ax.set_yticks(y, names, fontsize=8)
    if threshold is not None:
        ax.axvline(100 * threshold, color="tab:red", ls="--", lw=1, label=f"{100 * threshold:.0f}%")
    ax.set_xlabel("share of the objective f explained, % (orders the candidates; the tests decide)")
    ax.set_title(f"Round {rnd.number}: attribution of the residual (f = {rnd.f_base:.4g})")
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    return save_figure(fig, path)


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
        lines += [f"## Round {rnd.number}: {getattr(rnd, 'outcome', '') or 'verdict'}", "", rnd.verdict + ".", ""]
        lines += evidence_section(rnd)
        lines += reach_section(rnd)
        fig = ranking_figure(rnd, out / f"round{rnd.number}_attribution")
        lines += ["### Attribution (orders the candidates)", "",
                  "| effect | best hypothesis | share of f, linear (beyond base) | linear, alone | "
                  "fitted through the FMU |", "|---|---|---|---|---|"]
        for r in rnd.attribution.ranking:
            fit = "-" if r.share_fit is None else f"{100 * r.share_fit:.1f}%"
            lines.append(f"| {r.effect}: {CATALOGUE[r.effect].title} | {r.label} | {100 * r.share:.1f}% | "
                         f"{100 * r.share_alone:.1f}% | {fit} |")
        lines += ["", f"The base parameters alone, refitted linearly, would bring f from "
                      f"{rnd.attribution.f_base:.4g} to {rnd.attribution.f_base_refit:.4g}. The shares order "
                      f"the candidates that are taken through the extended identification; the tests above "
                      f"decide.", "", f"![attribution]({fig.name})", ""]
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


def _g(x, fmt=".3g") -> str:
    return "-" if x is None else format(float(x), fmt)


def reach_section(rnd) -> list:
    """What the record can reveal of each effect (identification.loop.reach)."""
    reaches = getattr(rnd, "reach", None) or []
    if not reaches:
        return []
    lines = ["### What this record can reveal", "",
             "The smallest size the tests above confirm in 90 % of records, from the information the record "
             "carries beyond the base's parameters (median over the effect's places, pitches and phases; the "
             "most favourable), against the size the effect reaches in service:", "",
             "| effect | a_90, median | most favourable | plausible | shows in | visible |",
             "|---|---|---|---|---|---|"]
    for r in reaches:
        lines.append(f"| {r.name} | {r.size_text(r.typical)} | {r.size_text(r.best)} | {r.size_text(r.plausible)} | "
                     f"{100 * r.share:.0f} % | {'yes' if r.visible else 'no'} |")
    return lines + [""]


def evidence_section(rnd) -> list:
    """The tests behind the verdict (identification.loop.evidence)."""
    lines = ["### Evidence", ""]
    nz = getattr(rnd, "noise", None)
    ex = getattr(rnd, "excess", None)
    if nz is not None and ex is not None:
        src = ("declared in meta.json (sensor.force_noise_std_N)" if nz.source == "declared"
               else "estimated from the residual's second differences")
        lines += [f"Noise per channel: {src}. The base was refitted to its own optimum first "
                  f"(S = sum r^2 / sigma^2: {_g(rnd.base_refined.get('S_start'), '.5g')} -> "
                  f"{_g(rnd.S_base, '.5g')} over {ex.dof} degrees of freedom)"
                  + (f"; {len(rnd.base_restarts)} restart(s) from a better base found through an extension"
                     if rnd.base_restarts else "") + ".", "",
                  "| channel | sigma, N | estimated, N | mean square / sigma^2 | Ljung-Box p | above the noise |",
                  "|---|---|---|---|---|---|"]
        for j, c in enumerate(FORCE_CHANNELS):
            lines.append(f"| {c.replace('transducer.', '')} | {nz.sigma[j]:.3g} | {nz.estimated[j]:.3g} | "
                         f"{ex.ratio[j]:.3g} | {ex.lb_p[j]:.2g} | {'yes' if ex.above[j] else 'no'} |")
        lines += ["", f"(above: mean square at least {EXCESS_MIN:g} sigma^2 and not white, Ljung-Box "
                      f"Bonferroni-corrected over the channels at {ALPHA:g}.)", ""]
    tests = getattr(rnd, "tests", [])
    if tests:
        lines += [f"Candidates through the extended identification (m = {rnd.hypotheses} hypotheses scanned; "
                  f"confirmed when the Bonferroni p < {ALPHA:g}, dBIC > 0, the held-out gain > 0 and no "
                  f"disturbance outside the catalogue does better):", "",
                  "| effect | q | S ext | dS | scale | dof | statistic T | p | Bonferroni p | dBIC | "
                  "held-out gain | verdict |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for t in tests:
            lr = t.lr
            ho = "-" if t.holdout is None else t.holdout.text()
            why = t.status
            lines.append(f"| {t.effect} ({t.label}) | {lr.q} | {t.S:.5g} | {lr.dS:.4g} | {lr.scale:.3g} | "
                         f"{lr.dof:.2f} | {lr.T:.4g} | {lr.p:.3g} | {lr.p_adj:.3g} | {lr.dbic:+.1f} | {ho} | "
                         f"{why} |")
        lines.append("")
    deps = getattr(rnd, "departures", [])
    if deps:
        lines += ["Disturbances outside the catalogue, fitted to the same residual:", "",
                  "| disturbance | statistic T | Bonferroni p | dBIC | detail |", "|---|---|---|---|---|"]
        for d in deps:
            det = ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in d.detail.items())
            lines.append(f"| {d.family}: {d.label} | {d.test.T:.4g} | {d.test.p_adj:.3g} | {d.test.dbic:+.1f} | "
                         f"{det} |")
        lines.append("")
    dropped = getattr(rnd, "dropped", [])
    if dropped:
        lines += ["Candidates dropped (the round went on):", ""]
        lines += [f"* {d['effect']} ({d['stage']}): {d['reason']}" for d in dropped]
        lines.append("")
    return lines


def _residual_section(rnd, out: Path) -> list:
    ra = rnd.residual
    if ra is None:
        return []
    lines = []
    try:
        from identification.loop.residual import describe

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
    state = "confirmed" if rnd.confirmed else "tested, not confirmed"
    lines = [f"### Extended model ({state})", "",
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
