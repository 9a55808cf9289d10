"""The statistics of a campaign (the paper's section 4): the results as one
table, and whether the contact models differ in their final objectives
(one-way ANOVA, and Kruskal-Wallis because the objectives are not normal)."""
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
