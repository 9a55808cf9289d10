"""The statistics of a campaign (the paper's section 4): the results as one
table, and whether the contact models differ in their final objectives:
one-way ANOVA and Kruskal-Wallis (the objectives are not normal) treat the
identifications as independent samples; the paired tests use that every
measurement is identified under every model (Friedman over the models, and
Wilcoxon's signed-rank test per pair of models on log f, Holm-adjusted), so
that the spread between measurements, which is larger than the one between
models, does not hide a model that fits better on each of them."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from lss_fmu.design import CORS, SYMBOL


def load_results(campaign: Path) -> pd.DataFrame:
    """One row per identification of a campaign folder (results/*.json)."""
    files = sorted((Path(campaign) / "results").glob("*.json"))
    if not files:
        raise FileNotFoundError(f"{campaign}/results holds no result: run `lss campaign` first")
    rows = []
    for f in files:
        r = json.loads(f.read_text())
        row = {"measurement": r.get("sorter", r["measurement"]), "records": len(r.get("records") or [1]),
               "number": r.get("number"), "model": r["model"], "f": r["f"],
               "f0": r["f0"], "nfev": r["nfev"], "wheel_type": r.get("wheel_type"),
               "coupling_type": r.get("coupling_type"), "layout": r.get("layout")}
        for k in CORS:
            sym = SYMBOL[k]
            row[sym] = r["values"].get(sym, np.nan)
            iv = (r.get("interval") or {}).get(sym) or {}
            row[f"{sym}_lower"], row[f"{sym}_upper"] = iv.get("lower", np.nan), iv.get("upper", np.nan)
            row[f"{sym}_identifiable"] = iv.get("identifiable")
        rows.append(row)
    return pd.DataFrame(rows).sort_values(["model", "number", "measurement"])


def model_tests(df: pd.DataFrame) -> dict:
    """Do the final objectives differ between contact models? ANOVA and Kruskal-Wallis."""
    groups = [g["f"].to_numpy() for _, g in df.groupby("model") if len(g) > 1]
    if len(groups) < 2:
        return {"anova_p": float("nan"), "kruskal_p": float("nan"), "note": "fewer than two models"}
    anova = stats.f_oneway(*groups)
    kw = stats.kruskal(*groups)
    return {"anova_F": float(anova.statistic), "anova_p": float(anova.pvalue),
            "kruskal_H": float(kw.statistic), "kruskal_p": float(kw.pvalue)}


def holm(p_values) -> np.ndarray:
    """Holm's step-down adjustment: the family-wise error of the set of tests
    stays at the level whatever their dependence."""
    p = np.asarray(p_values, float)
    order = np.argsort(p)
    adj = np.empty_like(p)
    running = 0.0
    for rank, k in enumerate(order):
        running = max(running, (len(p) - rank) * p[k])
        adj[k] = min(1.0, running)
    return adj


def paired_tests(df: pd.DataFrame) -> dict:
    """Do the models differ measurement by measurement? Only measurements
    identified under every model enter (the others are listed in
    `left_out`). `best`: on how many measurements each model has the lowest
    f; `friedman_p` (three models or more): whether the models' ranks differ;
    `pairs`: per pair, the median of f_a / f_b over the measurements and
    Wilcoxon's signed-rank p on log f, raw and Holm-adjusted over the pairs."""
    models = sorted(df["model"].unique())
    wide = df.pivot_table(index="measurement", columns="model", values="f", aggfunc="min")
    complete = wide.dropna()
    out = {"models": models, "n": int(len(complete)),
           "left_out": sorted(str(m) for m in wide.index.difference(complete.index))}
    if len(models) < 2 or len(complete) < 2:
        out["note"] = "fewer than two models or two measurements identified under every model"
        return out
    if not (complete.to_numpy() > 0).all():
        raise ValueError("paired_tests: every final objective f must be positive (the tests compare log f)")
    logf = np.log(complete[models].to_numpy())
    best = logf.argmin(axis=1)
    out["best"] = {m: int(np.sum(best == k)) for k, m in enumerate(models)}
    if len(models) >= 3:
        fr = stats.friedmanchisquare(*logf.T)
        out["friedman_chi2"], out["friedman_p"] = float(fr.statistic), float(fr.pvalue)
    pairs = []
    for a in range(len(models)):
        for b in range(a + 1, len(models)):
            d = logf[:, a] - logf[:, b]
            p = 1.0 if not np.any(d != 0) else float(stats.wilcoxon(d).pvalue)
            pairs.append({"a": models[a], "b": models[b], "median_ratio": float(np.exp(np.median(d))), "p": p})
    for pr, p_adj in zip(pairs, holm([pr["p"] for pr in pairs])):
        pr["p_holm"] = float(p_adj)
    out["pairs"] = pairs
    return out
