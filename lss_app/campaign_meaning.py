"""What a campaign's CoRs mean (the report's second half, issue 51):

* the restitution an impact really has under each law, beside the law's
  nominal value (lss_fmu.contact_laws.effective_restitution): two laws that
  fit the same records give different nominal CoRs for the same physics;
* where a CoR sits on the box of the design (0.2-0.9): a law whose nominal
  value is held there cannot reach the data;
* whether a CoR carries to another layout: its spread across the
  measurements against the width of one measurement's interval (a spread
  far beyond the intervals is the model's or the optimiser's, not noise);
* where the truth is known (an `answers/` folder beside the records, as the
  rig writes), the error of the effective restitution against the truth's;
* what the campaign cost.

Everything is read from the campaign's result files and the answer files;
nothing is simulated.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import numpy as np
import pandas as pd

from lss_fmu.contact_laws import LAWS, effective_restitution
from lss_fmu.design import COR_BOUNDS, CORS, SYMBOL

AT_BOUND = 0.005      # a value this close to 0.2 or 0.9 is held by the box
TARGET = 0.03         # the recovery table's tolerance on a CoR
CARRY = 2.0           # a CoR whose spread across measurements is within this many interval half-widths carries


class ReportError(ValueError):
    """A campaign folder or its answers that cannot make a report; the message names the file."""


def raw_results(campaign: Path) -> list[dict]:
    """The result files of a campaign (results/*.json), each with its path under `_file`."""
    files = sorted((Path(campaign) / "results").glob("*.json"))
    out = []
    for f in files:
        try:
            r = json.loads(f.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise ReportError(f"{f}: not a readable result file ({exc})") from None
        for key in ("model", "values"):
            if key not in r:
                raise ReportError(f"{f}: a result file without '{key}'")
        r["_file"] = str(f)
        out.append(r)
    return out


def truth_of(result: dict) -> Optional[dict]:
    """The answer file of a result's first record (DIR/answers/mNN/truth.json
    beside DIR/mNN), or None when there is none; an answer file of another
    measurement than the result's is refused."""
    records = result.get("records") or ([result["measurement_dir"]] if result.get("measurement_dir") else [])
    if not records:
        return None
    rec = Path(records[0])
    f = rec.parent / "answers" / rec.name / "truth.json"
    if not f.is_file():
        return None
    try:
        truth = json.loads(f.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ReportError(f"{f}: not a readable answer file ({exc})") from None
    if "cor" not in truth or "contact_law" not in truth:
        raise ReportError(f"{f}: an answer file needs 'cor' and 'contact_law'")
    if truth["contact_law"] not in LAWS:
        raise ReportError(f"{f}: contact_law = {truth['contact_law']!r} is not one of {', '.join(LAWS)}")
    number = result.get("number")
    if number is not None and truth.get("number") is not None and int(truth["number"]) != int(number):
        raise ReportError(f"{f}: the answers are for measurement {truth['number']}, the records "
                          f"({result['_file']}) for measurement {number}")
    return truth


def cor_rows(results: list[dict]) -> pd.DataFrame:
    """One row per result and CoR: nominal value, its interval and claim, the
    effective restitution, whether the box holds it, and against the truth
    (when known) the truth's effective restitution and the error."""
    rows = []
    for r in results:
        truth = truth_of(r)
        for name in CORS:
            sym = SYMBOL[name]
            v = r["values"].get(sym)
            if v is None:
                continue
            iv = (r.get("interval") or {}).get(sym) or {}
            row = {"model": r["model"], "measurement": r.get("sorter", r.get("measurement")), "cor": sym,
                   "nominal": float(v), "effective": effective_restitution(r["model"], float(v)),
                   "lower": iv.get("lower", np.nan), "upper": iv.get("upper", np.nan),
                   "claimed": iv.get("identifiable") is True,
                   "at_bound": min(abs(float(v) - b) for b in COR_BOUNDS) <= AT_BOUND,
                   "truth_effective": np.nan, "error": np.nan}
            if truth is not None and sym in truth["cor"]:
                row["truth_effective"] = effective_restitution(truth["contact_law"], float(truth["cor"][sym]))
                row["error"] = row["effective"] - row["truth_effective"]
            rows.append(row)
    return pd.DataFrame(rows)


def cor_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """Per model and CoR: medians of the nominal and effective values, how
    many sit on the box, how many are claimed, the claimed values' spread
    across measurements against their intervals' median half-width, and
    against the truth the median |error| and the claimed values within 0.03."""
    out = []
    for (model, sym), g in rows.groupby(["model", "cor"], sort=True):
        c = g[g["claimed"]]
        half = 0.5 * (c["upper"] - c["lower"])
        spread = float(c["nominal"].std(ddof=1)) if len(c) > 1 else np.nan
        width = float(half.median()) if len(c) else np.nan
        known = g["error"].notna()
        out.append({"model": model, "cor": sym, "n": len(g), "nominal": float(g["nominal"].median()),
                    "effective": float(g["effective"].median()), "at_bound": int(g["at_bound"].sum()),
                    "claimed": int(len(c)), "spread": spread, "half_width": width,
                    "spread_over_width": spread / width if width and width > 0 else np.nan,
                    "with_truth": int(known.sum()),
                    "median_abs_error": float(g.loc[known, "error"].abs().median()) if known.any() else np.nan,
                    "claimed_within": int((c["error"].abs() <= TARGET).sum()) if known.any() else 0})
    order = {SYMBOL[name]: k for k, name in enumerate(CORS)}
    df = pd.DataFrame(out)
    if df.empty:
        return df
    return df.sort_values(["model", "cor"], key=lambda col: col.map(order) if col.name == "cor" else col,
                          ignore_index=True)


def cost_summary(results: list[dict]) -> dict:
    """CPU per identification (the campaign's own count, `cpu_s`) per model and in all."""
    cpu = pd.DataFrame([{"model": r["model"], "cpu_s": r.get("cpu_s", np.nan)} for r in results])
    cpu = cpu.dropna()
    if cpu.empty:
        return {"total_cpu_s": np.nan}
    per = {m: {"n": int(len(g)), "median_cpu_s": float(g["cpu_s"].median()), "max_cpu_s": float(g["cpu_s"].max()),
               "total_cpu_s": float(g["cpu_s"].sum())} for m, g in cpu.groupby("model")}
    return {"per_model": per, "total_cpu_s": float(cpu["cpu_s"].sum()), "n": int(len(cpu))}


def _f(x, fmt=".3f") -> str:
    return "-" if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, fmt)


def meaning_text(summary: pd.DataFrame, cost: dict) -> list[str]:
    """The report's section on what the CoRs mean, as Markdown lines."""
    lines = ["## What the CoRs mean", "",
             "Per law and CoR: the median nominal value and the restitution an impact really has with it "
             "(docs/contact_laws.md); how many values the CoR box (0.2-0.9) holds on a bound (such a law cannot "
             "reach the data there); the spread of the claimed values across measurements against the median "
             "half-width of one measurement's 95 % interval (about 1 or below: the CoR carries to another layout; "
             "far above: the differences are the model's or the optimiser's, not the records' noise)."]
    truth = bool(summary["with_truth"].sum()) if not summary.empty else False
    if truth:
        lines[-1] += (" Where the records have answers, the median |error| of the effective restitution against "
                      "the truth's, and how many claimed values are within 0.03 of it.")
    head = ["law", "CoR", "n", "nominal", "effective", "on a bound", "claimed", "spread", "interval half-width",
            "spread / half-width"] + (["median abs error", "claimed within 0.03"] if truth else [])
    lines += ["", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, q in summary.iterrows():
        cells = [q["model"], q["cor"], str(q["n"]), _f(q["nominal"]), _f(q["effective"]), str(q["at_bound"]),
                 str(q["claimed"]), _f(q["spread"]), _f(q["half_width"]), _f(q["spread_over_width"], ".2g")]
        if truth:
            cells += [_f(q["median_abs_error"]), f"{q['claimed_within']} of {q['claimed']}"]
        lines.append("| " + " | ".join(cells) + " |")
    carry = summary[summary["spread_over_width"] <= CARRY]
    if not summary.empty:
        lines += ["", "CoRs that carry to another layout (spread across measurements at most "
                  f"{CARRY:g} x one interval's half-width): "
                  + ("; ".join(f"{m}: {', '.join(g['cor'])}" for m, g in carry.groupby("model"))
                     if len(carry) else "none") + "."]
    if np.isfinite(cost.get("total_cpu_s", np.nan)):
        per = "; ".join(f"{m}: median {_f(c['median_cpu_s'], '.0f')} CPU-s, max {_f(c['max_cpu_s'], '.0f')}"
                        for m, c in cost["per_model"].items())
        lines += ["", f"**Cost.** {cost['n']} identifications, {cost['total_cpu_s'] / 3600:.2f} CPU-hours in all "
                  f"({per})."]
    return lines
