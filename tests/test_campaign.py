"""The campaign: resumable after a kill, the same on local processes and on a
Dask cluster, and the report with its statistics (issue 6)."""
from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from identification.pipeline.campaign import CampaignError, run_campaign, sorters_in
from identification.pipeline.settings import Settings
from lss_app.campaign_report import write_report

# a campaign's settings for a test: short windows, a small complex, two CoRs free
SMALL = Settings(window=1.1, first_window=0.2, max_evals=6, refine_evals=0, restarts=0, shrink=False,
                 free=("contact.e_SW", "contact.e_RW"))
SECONDS = 1.1   # a start-stop stops at 1.0 s


@pytest.fixture(scope="module")
def data(tmp_path_factory, fmu_file):
    """Two sorters of layout 7 (measurements 20 and 21) with two start-stop
    records each: data/mNN and data_r1/mNN (lss rig --repeat 1)."""
    from lss_fmu.rig import run_measurement
    from lss_fmu.runner import ChainSimulator
    root = tmp_path_factory.mktemp("campaign_data")
    with ChainSimulator() as s:
        for repeat, folder in ((0, "data"), (1, "data_r1")):
            for n in (20, 21):
                run_measurement("recovery", n, root / folder, s, protocol="start-stop", lap_seconds=SECONDS,
                                repeat=repeat)
    return [root / "data", root / "data_r1"]


@pytest.fixture(scope="module")
def settings_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("campaign_settings") / "small.toml"
    path.write_text("[identify]\nwindow = 1.1\nfirst_window = 0.2\nmax_evals = 6\nrefine_evals = 0\n"
                    "restarts = 0\nshrink = false\nfree = [\"e_SW\", \"e_RW\"]\n")
    return path


@pytest.fixture(scope="module")
def reference(data, tmp_path_factory):
    out = tmp_path_factory.mktemp("campaign_ref")
    return out, run_campaign(data, ["LW", "HW"], out, settings=SMALL, workers=2, progress=False)


def _by_key(results):
    return {(r["sorter"], r["model"]): (r["f"], r["x"]) for r in results}


def test_campaign_results_and_report(reference):
    out, results = reference
    assert len(results) == 4
    assert {r["model"] for r in results} == {"LW", "HW"}
    for r in results:   # each sorter's two records fitted jointly, by the front door's method and settings
        assert r["sorter"] in ("m20", "m21") and len(r["records"]) == 2 and r["method"] == "grown"
        assert r["settings"] == SMALL.to_dict() and r["window_s"] == pytest.approx(SECONDS, abs=0.01)
    report = write_report(out)
    text = report.read_text()
    assert "One-way ANOVA" in text and "Kruskal-Wallis" in text
    stats = json.loads((out / "report" / "statistics.json").read_text())
    assert 0.0 <= stats["tests"]["anova_p"] <= 1.0
    assert "Paired over measurements" in text
    assert stats["paired"]["n"] == 2 and sum(stats["paired"]["best"].values()) == 2
    assert [(q["a"], q["b"]) for q in stats["paired"]["pairs"]] == [("HW", "LW")]
    # Fig. 8-10 for each law's median-f measurement (simulated again from its records), Fig. 11 over all
    shown = {r["model"]: r["sorter"] for r in results if r["f"] == min(q["f"] for q in results if q["model"] == r["model"])}
    for fig in ("objectives.png", "cor_e_SW.png", "cor_e_RW.png", "nrmsd_by_law.png",
                *(f"forces_{s}_{m}.png" for m, s in shown.items()), *(f"history_{s}_{m}.png" for m, s in shown.items())):
        assert (out / "report" / fig).stat().st_size > 1000


def test_killed_campaign_resumes_with_the_same_results(data, reference, settings_file, tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "lss_app.cli", "campaign", *map(str, data), "--models", "LW", "--out",
           str(out), "--workers", "1", "--settings", str(settings_file), "--no-progress"]
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
    assert len(before) == 1, "the kill came too late to test a resume"
    resumed = run_campaign(data, ["LW"], out, settings=SMALL, workers=1, progress=False)
    assert _by_key(resumed) == {k: v for k, v in _by_key(reference[1]).items() if k[1] == "LW"}


def test_campaign_on_a_local_dask_cluster(data, reference, tmp_path):
    from dask.distributed import Client, LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        results = run_campaign(data, ["HW"], tmp_path / "dask", settings=SMALL, client=client, progress=False)
    assert _by_key(results) == {k: v for k, v in _by_key(reference[1]).items() if k[1] == "HW"}


def test_campaign_refuses_bad_input(data, reference, tmp_path):
    kw = dict(progress=False)
    with pytest.raises(ValueError, match="unknown contact model 'XX'"):
        run_campaign(data, ["XX"], tmp_path / "x", settings=SMALL, **kw)
    with pytest.raises(FileNotFoundError, match="no such measurement folder"):
        run_campaign([tmp_path / "nothing"], ["LW"], tmp_path / "y", settings=SMALL, **kw)
    # a resume with other settings or another seed would mix two methods in one table
    out, _ = reference
    with pytest.raises(CampaignError, match=r"began with max_evals = 6, now 7"):
        run_campaign(data, ["LW"], out, settings=dataclasses.replace(SMALL, max_evals=7), **kw)
    with pytest.raises(CampaignError, match="began with seed 0, now 1"):
        run_campaign(data, ["LW"], out, settings=SMALL, seed=1, **kw)
    # records of different sorters under one name: the front door's check, naming both records
    from lss_fmu.rig import run_measurement
    from lss_fmu.runner import ChainSimulator
    mixed = tmp_path / "mixed"
    with ChainSimulator() as s:   # a layout-6 record filed under the name of a layout-7 one
        run_measurement("recovery", 19, mixed, s, protocol="start-stop", lap_seconds=SECONDS)
    (mixed / "m19").rename(mixed / "m20")
    with pytest.raises(CampaignError, match=r"sorter m20: .*mixed/m20: layout 'layout6' differs from"):
        run_campaign([data[0], mixed], ["LW"], tmp_path / "z", settings=SMALL, workers=1, **kw)
    # records of another protocol beside the start-stops: one campaign compares laws on one kind of record
    other = tmp_path / "start_up"
    with ChainSimulator() as s:
        run_measurement("recovery", 5, other, s, protocol="start-up", lap_seconds=0.3)
    with pytest.raises(CampaignError, match=r"mix records of different kinds: .*protocol 'start-stop'.*"
                                            r"protocol 'start-up'"):
        run_campaign([data[0], other], ["LW"], tmp_path / "k", settings=SMALL, workers=1, **kw)
    # a measurement missing from one data folder: its sorter would be fitted on fewer records than the others
    import shutil
    partial = tmp_path / "partial"
    shutil.copytree(data[1], partial)
    shutil.rmtree(partial / "m21")
    with pytest.raises(CampaignError, match=r"sorter m21 has 1 record\(s\) where others have 2"):
        run_campaign([data[0], partial], ["LW"], tmp_path / "p", settings=SMALL, workers=1, **kw)


def test_sorters_by_folder_name_and_by_manifest(data, tmp_path):
    from identification.pipeline.campaign import sorters_of_manifest
    sorters = sorters_in(data)
    assert [s.name for s in sorters] == ["m20", "m21"]
    assert [[Path(r).parent.name for r in s.records] for s in sorters] == [["data", "data_r1"]] * 2
    manifest = tmp_path / "sorters.toml"
    manifest.write_text(f'[sorters]\nline_a = ["{data[0] / "m20"}", "{data[1] / "m20"}"]\n')
    assert sorters_of_manifest(manifest)[0].records == sorters[0].records
    manifest.write_text('[sorters]\nline_a = ["nowhere/m01"]\n')
    with pytest.raises(CampaignError, match=r"sorters.line_a: .*nowhere/m01 is not a measurement folder"):
        sorters_of_manifest(manifest)
    manifest.write_text('[sorters]\n"line a/b" = ["x"]\n')
    with pytest.raises(CampaignError, match="sorter name 'line a/b'"):
        sorters_of_manifest(manifest)
    manifest.write_text('[sorter]\nline_a = []\n')
    with pytest.raises(CampaignError, match=r"sorters.toml: needs a \[sorters\] table"):
        sorters_of_manifest(manifest)
