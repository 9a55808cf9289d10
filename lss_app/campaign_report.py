"""The campaign report (the paper's section 4) from a campaign's results: a
Table-3 style CoR table per model, the final objectives per model with the
tests of identification.pipeline.stats (unpaired and paired over the
measurements), what the CoRs mean (lss_app.campaign_meaning: effective
restitution, the box, spread against intervals, errors against answers,
cost), and box plots of the CoRs per contact class and per wheel or joint
type with the bounds drawn (Figs. 12-16). One Markdown report with its
figures; the per-law CoR summary also as cors.csv.

    lss report CAMPAIGN_DIR
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import pandas as pd

from identification.pipeline.stats import load_results, model_tests, paired_tests
from lss_app.campaign_figures import nrmsd_by_law, shown, single_figures
from lss_app.campaign_meaning import cor_rows, cor_summary, cost_summary, meaning_text, raw_results
from lss_fmu.atomic import write_atomic, write_json_atomic
from lss_fmu.design import COR_BOUNDS


def _box(ax, data: dict, title: str, bounds=None, log=False):
    labels = list(data)
    ax.boxplot([np.asarray(data[k], float) for k in labels], tick_labels=labels)
    if bounds:
        for b in bounds:
            ax.axhline(b, ls=":", color="k", lw=1)
    if log:
        ax.set_yscale("log")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)


def make_figures(df: pd.DataFrame, out: Path) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    figs = []
    fig, ax = plt.subplots(figsize=(6, 4))
    _box(ax, {m: g["f"] for m, g in df.groupby("model")}, "final objectives per contact model", log=True)
    fig.tight_layout()
    fig.savefig(out / "objectives.png", dpi=100)
    fig.savefig(out / "objectives.svg")
    plt.close(fig)
    figs.append("objectives.png")
    for short, group_col in (("e_JA", "coupling_type"), ("e_JR", "coupling_type"),
                             ("e_SW", "wheel_type"), ("e_RW", "wheel_type")):
        types = sorted(t for t in df[group_col].dropna().unique())
        fig, axes = plt.subplots(1, max(1, len(types)), figsize=(4.5 * max(1, len(types)), 3.8), squeeze=False)
        for ax, t in zip(axes[0], types or [None]):
            sub = df if t is None else df[df[group_col] == t]
            _box(ax, {m: g[short] for m, g in sub.groupby("model")},
                 f"{short}, {group_col.replace('_', ' ')} {t} (n={len(sub) // max(1, sub['model'].nunique())})",
                 bounds=COR_BOUNDS)
            ax.set_ylim(0, 1)
        fig.tight_layout()
        name = f"cor_{short}.png"
        fig.savefig(out / name, dpi=100)
        fig.savefig(out / name.replace(".png", ".svg"))
        plt.close(fig)
        figs.append(name)
    return figs


def _cell(row, sym: str) -> str:
    v, lo, hi, ok = row[sym], row.get(f"{sym}_lower"), row.get(f"{sym}_upper"), row.get(f"{sym}_identifiable")
    if ok is None or (isinstance(ok, float) and np.isnan(ok)):
        return f"{v:.3f}"
    return f"{v:.3f} [{lo:.3f}, {hi:.3f}]" if ok else f"n.i. ({v:.3f})"


def _cor_table(g: pd.DataFrame) -> str:
    syms = ("e_JA", "e_JR", "e_SW", "e_RW")
    lines = ["| measurement | " + " | ".join(syms) + " | f |", "|---" * (len(syms) + 2) + "|"]
    for _, row in g.iterrows():
        lines.append(f"| {row['measurement']} | " + " | ".join(_cell(row, s) for s in syms) + f" | {row['f']:.4g} |")
    return "\n".join(lines)


def _paired_text(paired: dict) -> list:
    """The paired tests as the report's prose and table (stats.paired_tests)."""
    if "pairs" not in paired:
        return [f"No paired test: {paired.get('note', 'not enough results')}."]
    n, lines = paired["n"], []
    best = ", ".join(f"{m} on {k}" for m, k in sorted(paired["best"].items(), key=lambda kv: -kv[1]))
    lines.append(f"Each of the {n} measurements identified under every model is a block: the lowest f is reached by "
                 f"{best}." + (f" Left out (not identified under every model): {', '.join(paired['left_out'])}."
                               if paired["left_out"] else ""))
    if "friedman_p" in paired:
        verdict = "the models' ranks differ" if paired["friedman_p"] < 0.05 else "no model ranks consistently better"
        lines.append(f"Friedman's test over the models: chi2 = {paired['friedman_chi2']:.3g}, "
                     f"p = {paired['friedman_p']:.3g}: at the 5 % level {verdict}.")
    lines.append(_verdict(paired))
    lines += ["", "Per pair, the median of f_a / f_b over the measurements and Wilcoxon's signed-rank test on log f "
              "(p adjusted by Holm over the pairs):", "",
              "| a | b | median f_a / f_b | p | p (Holm) |", "|---|---|---|---|---|"]
    lines += [f"| {q['a']} | {q['b']} | {q['median_ratio']:.3g} | {q['p']:.3g} | {q['p_holm']:.3g} |"
              for q in paired["pairs"]]
    return lines


def _verdict(paired: dict) -> str:
    """Which law fits best, and the test behind it: the law lowest on the most
    measurements fits best when it is lower than every other law on the
    measurements (median ratio below 1) with Holm-adjusted p < 0.05 each."""
    lead = max(paired["best"], key=lambda m: paired["best"][m])
    against = [q for q in paired["pairs"] if lead in (q["a"], q["b"])]
    ratio = {(q["b"] if q["a"] == lead else q["a"]): (q["median_ratio"] if q["a"] == lead else 1 / q["median_ratio"],
                                                      q["p_holm"]) for q in against}
    if all(r < 1 and p < 0.05 for r, p in ratio.values()):
        worst = max(p for _, p in ratio.values())
        return (f"**{lead} fits best**: lowest f on {paired['best'][lead]} of {paired['n']} measurements, below every "
                f"other law measurement by measurement (Holm-adjusted Wilcoxon p <= {worst:.2g}).")
    weak = ", ".join(f"{m} (f ratio {r:.3g}, p {p:.2g})" for m, (r, p) in ratio.items() if not (r < 1 and p < 0.05))
    return (f"**No law fits significantly better than all others**: {lead} is lowest on {paired['best'][lead]} of "
            f"{paired['n']} measurements but not significantly below {weak} at the 5 % level.")


def write_report(campaign: Path, show: Optional[Sequence[str]] = None) -> Path:
    """The report of a campaign folder into CAMPAIGN/report/ (report.md, figures, statistics.json,
    cors.csv); `show`: the measurements drawn whole per law (default: each law's median-f one)."""
    campaign = Path(campaign)
    df = load_results(campaign)
    out = campaign / "report"
    out.mkdir(exist_ok=True)
    tests = model_tests(df)
    figs = make_figures(df, out)
    lines = ["# Campaign report", "",
             f"{df['measurement'].nunique()} measurements x {df['model'].nunique()} contact models "
             f"({len(df)} identifications) from `{campaign}`.", "",
             "## Final objectives per contact model", "", "![objectives](objectives.png)", ""]
    summ = df.groupby("model")["f"].describe()[["count", "mean", "std", "25%", "50%", "75%"]]
    lines += [summ.to_markdown(floatfmt=".4g"), ""]
    lines += [f"One-way ANOVA on the final objectives: F = {tests.get('anova_F', float('nan')):.3g}, "
              f"p = {tests['anova_p']:.3g}. Kruskal-Wallis (rank-based): H = {tests.get('kruskal_H', float('nan')):.3g}, "
              f"p = {tests['kruskal_p']:.3g}. "
              + ("No model is statistically better at the 5 % level."
                 if tests["anova_p"] >= 0.05 and tests["kruskal_p"] >= 0.05
                 else "At the 5 % level the models differ."), ""]
    paired = paired_tests(df)
    lines += ["## Paired over measurements", "", *_paired_text(paired), ""]
    for model, g in df.groupby("model"):
        lines += [f"## Coefficients of restitution, model {model}", "",
                  "Each CoR with its 95 % interval (identification.objective.uncertainty); *n.i.*: the record does not "
                  "pin it down (interval wider than 40 % of the bounds, or the record is chaotic in it).", ""]
        lines += [_cor_table(g), ""]
    raw = raw_results(campaign)
    summary, cost = cor_summary(cor_rows(raw)), cost_summary(raw)
    lines += [*meaning_text(summary, cost), ""]
    lines += ["## One measurement per law, whole (Fig. 8-10)", "",
              "The measured forces (grey band: +-2 sensor sigma) against the simulations at the start and at the "
              "optimum, as the objective compares them (tared), on the window the result is for; then the "
              "objective of every evaluation. NRMSD per channel, start and optimum, over every measurement of a "
              "law (Fig. 11) below.", ""]
    for r in shown(raw, show):
        figs_r, note = single_figures(r, out)
        lines += [f"### {r.get('sorter', r.get('measurement'))}, {r['model']}: f {r['f']:.4g}", ""]
        lines += [f"![{f}]({f})" for f in figs_r] + ([note] if note else []) + [""]
    nr = nrmsd_by_law(raw, out)
    if nr:
        lines += [f"![NRMSD per channel]({nr})", ""]
    lines += ["## CoRs per contact class and cart type (bounds dotted)", ""]
    lines += [f"![{f}]({f})" for f in figs[1:]] + [""]
    write_atomic(out / "report.md", "\n".join(lines))
    summary.to_csv(out / "cors.csv", index=False)
    write_json_atomic(out / "statistics.json", {"tests": tests, "paired": paired, "cost": cost,
                                                "cors": summary.to_dict("records"), "summary": summ.reset_index().to_dict("records")})
    return out / "report.md"
