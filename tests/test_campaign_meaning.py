"""What a campaign's CoRs mean (lss_app.campaign_meaning): the effective
restitution beside the nominal value, the box, the spread across
measurements against the intervals, the error against answer files, the
cost; an answer file of another measurement is refused. Campaign folders
are written by hand here: nothing is simulated."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from lss_app.campaign_figures import shown
from lss_app.campaign_meaning import ReportError, cor_rows, cor_summary, cost_summary, raw_results, truth_of
from lss_app.campaign_report import write_report
from lss_fmu.contact_laws import effective_restitution

SYMS = ("e_JA", "e_JR", "e_SW", "e_RW")


def write_campaign(root: Path, values: dict, truth: dict | None, half: float = 0.02, number_shift: int = 0,
                   cpu: float = 100.0) -> Path:
    """values: {(model, k): {sym: value}}; truth: {k: (law, {sym: value})} written as answers beside
    each measurement's record folder (numbered k + number_shift in the answer file)."""
    camp, data = root / "camp", root / "data"
    (camp / "results").mkdir(parents=True)
    for (model, k), vals in values.items():
        rec = data / f"m{k:02d}"
        rec.mkdir(parents=True, exist_ok=True)
        if truth is not None and k in truth:
            (data / "answers" / rec.name).mkdir(parents=True, exist_ok=True)
            law, cor = truth[k]
            (data / "answers" / rec.name / "truth.json").write_text(
                json.dumps({"number": k + number_shift, "contact_law": law, "cor": cor}))
        interval = {s: {"lower": v - half, "upper": v + half, "identifiable": True} for s, v in vals.items()}
        result = {"model": model, "sorter": rec.name, "measurement": rec.name, "number": k, "records": [str(rec)],
                  "values": vals, "interval": interval, "f": 1.0 + k, "f0": 10.0, "nfev": 100, "cpu_s": cpu,
                  "wheel_type": "A", "coupling_type": "B", "layout": "layout7"}
        (camp / "results" / f"{rec.name}_{model}.json").write_text(json.dumps(result))
    return camp


def test_effective_restitution_sits_beside_the_nominal_value(tmp_path):
    camp = write_campaign(tmp_path, {("LW", 1): {"e_SW": 0.2}, ("HW", 1): {"e_SW": 0.2}}, truth=None)
    rows = cor_rows(raw_results(camp)).set_index("model")
    assert rows.loc["LW", "effective"] == pytest.approx(effective_restitution("LW", 0.2))
    assert rows.loc["LW", "effective"] > 0.65          # LW cannot dissipate much: 0.2 restitutes about 0.7
    assert rows.loc["HW", "effective"] == pytest.approx(effective_restitution("HW", 0.2))
    assert rows["at_bound"].all()                      # 0.2 is on the box
    assert rows["error"].isna().all()                  # no answers: no errors


def test_errors_against_the_truth_use_the_effective_restitution(tmp_path):
    # the truth under GZ (its effective restitution is its nominal value); HC found the same physics
    truth = {k: ("GZ", {"e_SW": 0.7, "e_RW": 0.8}) for k in (1, 2, 3)}
    e_hc = brentq(lambda e: effective_restitution("HC", e) - 0.7, 1e-6, 0.999)
    off = brentq(lambda e: effective_restitution("HC", e) - 0.75, 1e-6, 0.999)
    found = {("HC", k): {"e_SW": e, "e_RW": 0.8} for k, e in zip((1, 2, 3), (e_hc, e_hc, off))}
    camp = write_campaign(tmp_path, found, truth)
    summary = cor_summary(cor_rows(raw_results(camp))).set_index("cor")
    assert summary.loc["e_SW", "with_truth"] == 3
    assert e_hc < 0.6                                           # the nominal values differ from the truth's...
    assert summary.loc["e_SW", "claimed_within"] == 2          # ...the physics does: two exact, one 0.05 off
    assert summary.loc["e_SW", "median_abs_error"] == pytest.approx(0.0, abs=1e-9)
    # e_RW = 0.8 nominal under HC is not 0.8 effective: a nominal agreement is not the physics'
    assert summary.loc["e_RW", "median_abs_error"] == pytest.approx(effective_restitution("HC", 0.8) - 0.8)
    assert summary.loc["e_RW", "claimed_within"] == 0


def test_spread_against_the_intervals(tmp_path):
    rng = np.random.default_rng(0)
    vals = 0.5 + 0.05 * rng.standard_normal(8)
    camp = write_campaign(tmp_path, {("HW", k): {"e_JA": float(v)} for k, v in enumerate(vals, 1)}, None,
                          half=0.01)
    q = cor_summary(cor_rows(raw_results(camp))).iloc[0]
    assert q["spread"] == pytest.approx(np.std(vals, ddof=1))
    assert q["half_width"] == pytest.approx(0.01)
    assert q["spread_over_width"] == pytest.approx(np.std(vals, ddof=1) / 0.01)


def test_answers_of_another_measurement_are_refused_naming_the_file(tmp_path):
    camp = write_campaign(tmp_path, {("LW", 4): {"e_SW": 0.4}}, {4: ("LW", {"e_SW": 0.4})}, number_shift=1)
    with pytest.raises(ReportError, match=r"answers/m04/truth.json: the answers are for measurement 5"):
        truth_of(raw_results(camp)[0])


def test_a_result_file_without_values_is_refused(tmp_path):
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "x.json").write_text(json.dumps({"model": "LW"}))
    with pytest.raises(ReportError, match="x.json: a result file without 'values'"):
        raw_results(tmp_path)


def test_the_report_states_the_meaning_and_the_cost(tmp_path):
    values = {(m, k): {s: 0.3 + 0.1 * k for s in SYMS} for m in ("HW", "LW") for k in (1, 2, 3)}
    truth = {k: ("LW", {s: 0.3 + 0.1 * k for s in SYMS}) for k in (1, 2, 3)}
    camp = write_campaign(tmp_path, values, truth, cpu=120.0)
    text = write_report(camp).read_text()
    assert "## What the CoRs mean" in text and "claimed within 0.03" in text
    assert "6 identifications, 0.20 CPU-hours" in text
    assert cost_summary(raw_results(camp))["per_model"]["LW"]["median_cpu_s"] == 120.0
    csv = (camp / "report" / "cors.csv").read_text().splitlines()
    assert csv[0].startswith("model,cor,n,nominal,effective") and len(csv) == 1 + 2 * len(SYMS)
    stats = json.loads((camp / "report" / "statistics.json").read_text())
    lw_sw = next(q for q in stats["cors"] if q["model"] == "LW" and q["cor"] == "e_SW")
    assert lw_sw["claimed_within"] == 3 and lw_sw["median_abs_error"] == pytest.approx(0.0)
    # the records here are empty folders: the overlays are said to be missing, the report is still written
    assert text.count("no force overlay") == 2


def test_the_measurement_shown_whole_is_each_laws_median_or_the_named_one(tmp_path):
    values = {(m, k): {"e_SW": 0.5} for m in ("HW", "LW") for k in (1, 2, 3, 4)}
    results = raw_results(write_campaign(tmp_path, values, None))   # f = 1 + k
    assert [(r["model"], r["sorter"]) for r in shown(results)] == [("HW", "m02"), ("LW", "m02")]
    assert [(r["model"], r["sorter"]) for r in shown(results, ["m04"])] == [("HW", "m04"), ("LW", "m04")]
