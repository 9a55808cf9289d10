"""Figures and numbers of docs/contact_laws.md.

    lss figures contact-laws [--out docs/figures] [--table]

writes
  restitution_laws.png/.svg   effective restitution v_out/v_in against the
                              nominal e for every law: lines from the exact
                              relation, markers from the C single-impact
                              harness, the diagonal, the range of the
                              identified CoRs of the paper's Table 3;
                              right panel: the deviation e_eff - e
  restitution_loops.png/.svg  force against indentation of one impact at
                              e = 0.5 for every law (C harness traces)
and prints the tables quoted in the document (--table: as Markdown).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from lss_fmu import contact_laws as cl

ROOT = Path(__file__).resolve().parents[2]
FIG_DIR = ROOT / "docs" / "figures"

COLORS = {"HC": "tab:blue", "HW": "tab:orange", "LW": "tab:green", "LN": "tab:red", "GZ": "black",
          "FL": "tab:purple"}
STYLES = {"GZ": "--"}
TABLE3_RANGE = (0.2, 0.9)    # range of the identified CoRs (paper, Table 3)
TABLE3_MEDIAN = 0.5          # about their median


def curves(e: np.ndarray) -> dict[str, np.ndarray]:
    return {law: np.array([cl.effective_restitution(law, x) for x in e]) for law in cl.LAWS}


def harness_points(e: np.ndarray, n: float = 1.5, tol: float = 1e-8) -> dict[str, np.ndarray]:
    return {law: np.array([cl.simulate_impact(law, x, n=n, tol=tol).e_eff for x in e]) for law in cl.LAWS}


def nominal_for(law: str, e_true: float) -> float:
    """The nominal e a law needs for a true restitution e_true (NaN if the law
    cannot dissipate that much for any e in (0, 1])."""
    from scipy.optimize import brentq
    f = lambda x: cl.effective_restitution(law, x) - e_true
    lo, hi = 1e-6, 1.0
    if f(lo) > 0:   # even e -> 0 restitutes more than e_true
        return float("nan")
    return brentq(f, lo, hi, xtol=1e-12)


def make_figures(out: Path = FIG_DIR) -> list[Path]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    e = np.linspace(0.01, 1.0, 300)
    ec = curves(e)
    ep = np.round(np.arange(0.1, 0.95, 0.1), 2)
    pts = harness_points(ep)

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 5.6), constrained_layout=True)
    for ax in (a, b):
        ax.axvspan(*TABLE3_RANGE, color="0.92", zorder=0)
        ax.axvline(TABLE3_MEDIAN, color="0.6", lw=0.8, ls=":", zorder=1)
    a.plot([0, 1], [0, 1], color="0.75", lw=4, label="diagonal $e_{eff} = e$", zorder=1.5)
    for law in cl.LAWS:
        c = COLORS[law]
        a.plot(e, ec[law], color=c, ls=STYLES.get(law, "-"), lw=1.6, label=f"{law}  {cl.LAW_TITLES[law]}")
        a.plot(ep, pts[law], "o", color=c, ms=4, mfc="none")
        b.plot(e, ec[law] - e, color=c, ls=STYLES.get(law, "-"), lw=1.6)
        b.plot(ep, pts[law] - ep, "o", color=c, ms=4, mfc="none")
    a.plot([], [], "o", color="0.3", mfc="none", ms=4, label="C single-impact harness (n = 1.5)")
    a.set(xlim=(0, 1), ylim=(0, 1), aspect="equal", xlabel="nominal coefficient of restitution $e$",
          ylabel="effective restitution $v_{out}/v_{in}$",
          title="Restitution each damping law really produces")
    a.text(0.55, 0.04, "grey band: identified CoRs\nof the paper's Table 3", fontsize=8, color="0.35")
    fig.legend(*a.get_legend_handles_labels(), loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    b.axhline(0, color="0.5", lw=1)
    b.set(xlim=(0, 1), xlabel="nominal coefficient of restitution $e$", ylabel="$e_{eff} - e$",
          title="Above 0: the law dissipates less than e says (under-damps)")
    for ax in (a, b):
        ax.grid(alpha=0.3)
    paths = []
    for ext in ("png", "svg"):
        p = out / f"restitution_laws.{ext}"
        fig.savefig(p, dpi=150)
        paths.append(p)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.4, 4.6), constrained_layout=True)
    K, n, m, v = 1e6, 1.5, 1.0, 1.0
    d_star = ((n + 1) * m * v * v / (2 * K)) ** (1 / (n + 1))
    for law in cl.LAWS:
        r = cl.simulate_impact(law, 0.5, K=K, n=n, m=m, v_i=v, tol=1e-9, h_max=d_star / v / 40, trace=4000)
        t, d, dd, F = r.trace.T
        keep = d > 0
        ax.plot(d[keep] / d_star, F[keep] / (K * d_star ** n), color=COLORS[law], ls=STYLES.get(law, "-"),
                label=f"{law}: $e_{{eff}}$ = {r.e_eff:.3f}")
    x = np.linspace(0, 1, 100)
    ax.plot(x, x ** n, color="0.6", lw=1, ls=":", label="elastic $K\\delta^n$")
    ax.set(xlabel="indentation $\\delta / \\delta^*$", ylabel="force $F / (K \\delta^{*n})$",
           title="One impact at nominal e = 0.5 (n = 1.5)", xlim=(0, None), ylim=(0, None))
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    for ext in ("png", "svg"):
        p = out / f"restitution_loops.{ext}"
        fig.savefig(p, dpi=150)
        paths.append(p)
    plt.close(fig)
    return paths


def tables(markdown: bool = False) -> str:
    lines = []
    es = [0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]
    head = ["law", "chi(0.5)"] + [f"e={x:g}" for x in es] + ["e -> 0 limit"]
    rows = []
    for law in cl.LAWS:
        lim = cl.effective_restitution(law, 1e-9)
        rows.append([law, f"{cl.chi(law, 0.5):.4f}"] + [f"{cl.effective_restitution(law, x):.3f}" for x in es]
                    + [f"{lim:.3f}"])
    sep = "|" if markdown else " "
    lines.append(sep.join(head))
    if markdown:
        lines[-1] = "| " + " | ".join(head) + " |"
        lines.append("|" + "---|" * len(head))
        lines += ["| " + " | ".join(r) + " |" for r in rows]
    else:
        lines += ["  ".join(f"{c:>9}" for c in r) for r in rows]
    lines.append("")
    head2 = ["law"] + [f"true {x:g}" for x in (0.3, 0.5, 0.7)]
    if markdown:
        lines.append("| nominal e needed for a true restitution of | " + " | ".join(head2[1:]) + " |")
        lines.append("|" + "---|" * len(head2))
    for law in cl.LAWS:
        vals = [nominal_for(law, x) for x in (0.3, 0.5, 0.7)]
        txt = ["impossible" if np.isnan(v) else f"{v:.3f}" for v in vals]
        lines.append(("| " + law + " | " + " | ".join(txt) + " |") if markdown else f"{law:>4} " + "  ".join(txt))
    return "\n".join(lines)


def accuracy(markdown: bool = False) -> str:
    """Largest |e_eff - e_pred| of the harness over the issue's grid (all laws,
    e = 0.2..0.9, n = 1 and 1.5) against the solver tolerance: with the
    impact's natural error scales, and with the chain's error scales at a
    steering-wheel-like contact (K = 4e7 N/m^1.5, m = 20 kg, v_i = 0.05 m/s);
    for the chain's onset rule and the cubic Hermite alternative."""
    grid = [(law, n, x) for law in cl.LAWS for n in (1.0, 1.5) for x in np.round(np.arange(0.2, 0.95, 0.1), 2)]
    pred = {(law, x): cl.effective_restitution(law, x) for law, _, x in grid}
    chain = dict(K=4e7, m=20.0, v_i=0.05, h_max=0.01, scale_delta=1e-2, scale_rate=1e-2, rel_rate=1.0)
    rows = []
    for tol in (1e-4, 1e-6, 1e-8):
        row = [f"{tol:g}"]
        for kw in ({}, chain):
            for rule in (0, 1):
                worst, steps = 0.0, []
                for law, n, x in grid:
                    r = cl.simulate_impact(law, x, n=n, tol=tol, onset_rule=rule, v_min=1e-3, **kw)
                    worst = max(worst, abs(r.e_eff - pred[law, x]))
                    steps.append(r.n_steps)
                row.append(f"{worst:.1e} ({np.mean(steps):.0f})")
        rows.append(row)
    head = ["tol", "natural, chain onset", "natural, Hermite onset", "chain scales, chain onset",
            "chain scales, Hermite onset"]
    if markdown:
        return "\n".join(["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
                         + ["| " + " | ".join(r) + " |" for r in rows])
    return "\n".join(["  ".join(head)] + ["  ".join(r) for r in rows])
