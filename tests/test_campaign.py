"""The campaign: resumable after a kill, the same on local processes and on a
Dask cluster, and the report with its statistics (issue 6)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from identification.campaign import run_campaign
from lss_app.campaign_report import write_report

SMALL = dict(max_evals=4, window=0.2, settle=0.05, free=("contact.e_SW", "contact.e_RW"), progress=False)


def _write_measurement(folder: Path, mid: str, number: int, e_sw: float) -> None:
    from lss_fmu.runner import LazySimulator
    from lss_fmu.measurement import write_measurement
    from lss_fmu.triggered import simulate_triggered
    from lss_fmu.variables import FORCE_CHANNELS, SPEED_CHANNELS
    t = np.arange(0, 0.25, 1 / 300)
    params = {"layout.name": "layout7", "contact.model": 3, "contact.e_SW": e_sw, "chain.pretension": 0.03}
    sig = simulate_triggered(LazySimulator()(), params, 0.3, t, settle=0.05, channels=FORCE_CHANNELS + SPEED_CHANNELS)
    df = pd.DataFrame(np.round(sig, 3), columns=FORCE_CHANNELS + SPEED_CHANNELS)
    df.insert(0, "time", t)
    meta = {"format_version": 1, "id": mid, "number": number, "layout": "layout7", "wheel_type": "C",
            "coupling_type": "A", "speed_nominal": 2.0, "pretension_nominal": 0.03, "sample_rate": 300.0,
            "trigger_point": 0.3, "date": "2026-11-22"}
    write_measurement(folder / mid, df, meta)


@pytest.fixture(scope="module")
def data(tmp_path_factory, fmu_file):
    root = tmp_path_factory.mktemp("campaign_data")
    _write_measurement(root, "m01", 1, 0.35)
    _write_measurement(root, "m02", 2, 0.6)
    return root


@pytest.fixture(scope="module")
def reference(data, tmp_path_factory):
    out = tmp_path_factory.mktemp("campaign_ref")
    return out, run_campaign(data, ["LW", "HW"], out, workers=2, **SMALL)


def _by_key(results):
    return {(r["measurement"], r["model"]): (r["f"], r["x"]) for r in results}


def test_campaign_results_and_report(reference):
    out, results = reference
    assert len(results) == 4
    assert {r["model"] for r in results} == {"LW", "HW"}
    report = write_report(out)
    text = report.read_text()
    assert "One-way ANOVA" in text and "Kruskal-Wallis" in text
    stats = json.loads((out / "report" / "statistics.json").read_text())
    assert 0.0 <= stats["tests"]["anova_p"] <= 1.0
    for fig in ("objectives.png", "cor_e_SW.png", "cor_e_RW.png"):
        assert (out / "report" / fig).stat().st_size > 1000


def test_killed_campaign_resumes_with_the_same_results(data, reference, tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "lss_app.cli", "campaign", str(data), "--models", "LW,HW", "--out", str(out),
           "--workers", "1", "--max-evals", "4", "--window", "0.2", "--settle", "0.05", "--free", "e_SW,e_RW",
           "--no-progress"]
    proc = subprocess.Popen(cmd, start_new_session=True)
    deadline = time.time() + 300
    # kill it once the first identification is done and the second has begun journaling
    while time.time() < deadline and proc.poll() is None:
        journals = list((out / "journals").glob("*.jsonl")) if (out / "journals").exists() else []
        results = list((out / "results").glob("*.json")) if (out / "results").exists() else []
        if results and len(journals) >= 2 and any(j.stat().st_size > 0 for j in journals
                                                  if j.stem + ".json" not in {r.name for r in results}):
            os.killpg(proc.pid, signal.SIGKILL)
            break
        time.sleep(0.05)
    proc.wait()
    before = {p.name for p in (out / "results").glob("*.json")}
    assert 1 <= len(before) < 4, "the kill came too late to test a resume"
    journal_lines = {p.name: len(p.read_text().splitlines()) for p in (out / "journals").glob("*.jsonl")}
    resumed = run_campaign(data, ["LW", "HW"], out, workers=1, **SMALL)
    assert _by_key(resumed) == _by_key(reference[1])
    for r in resumed:
        key = f"{r['measurement']}_{r['model']}"
        if key + ".json" not in before and journal_lines.get(key + ".jsonl", 0) > 0:
            assert r["replayed"] >= journal_lines[key + ".jsonl"] - 1  # nothing journaled was simulated again


def test_campaign_on_a_local_dask_cluster(data, reference, tmp_path):
    from dask.distributed import Client, LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        results = run_campaign(data, ["LW", "HW"], tmp_path / "dask", client=client, **SMALL)
    assert _by_key(results) == _by_key(reference[1])


def test_campaign_refuses_bad_input(data, tmp_path):
    with pytest.raises(ValueError, match="unknown contact model 'XX'"):
        run_campaign(data, ["XX"], tmp_path / "x", **SMALL)
    with pytest.raises(FileNotFoundError, match="no such measurement folder"):
        run_campaign(tmp_path / "nothing", ["LW"], tmp_path / "y", **SMALL)
