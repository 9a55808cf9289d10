"""The front door with nothing but its defaults: `lss identify REC --model LW
--out DIR` on a short start-stop of layout 2 (169 carts; the rig's record,
the transducer where the rig parked it), the ten design variables free,
reaches the noise and claims the three CoRs the record carries, each within
0.03 of the truth and each interval holding it. The truth is read here,
after the command, from the answer file it never sees. (The rate over
single 1.5 s records of other layouts is in docs/identification.md, "What a
record can tell".)"""
from __future__ import annotations

import json

from lss_app.cli import main
from lss_fmu.rig import load_truth, true_design_values

SECONDS = 1.5   # a short record: the default window (2.5 s) is cut to it


def test_the_default_command_recovers_a_start_stop(rig_record, tmp_path):
    rec = rig_record(5, "start-stop", SECONDS)
    out = tmp_path / "out"
    assert main(["identify", str(rec.path), "--model", "LW", "--out", str(out), "--no-progress"]) == 0
    res = json.loads((out / "result.json").read_text())
    assert res["method"] == "grown" and res["settings"]["window"] == 2.5 and len(res["free"]) == 10
    truth = true_design_values(load_truth(rec))
    for name in ("contact.e_JA", "contact.e_SW", "contact.e_RW"):   # claimed, within 0.03, the truth inside
        iv = res["interval"][name.split(".")[1]]
        assert iv["identifiable"] and iv["lower"] <= truth[name] <= iv["upper"], (name, truth[name], iv)
        assert abs(res["x"][name] - truth[name]) <= 0.03, (name, res["x"][name], truth[name], res["message"])
    for fig in ("forces", "history", "nrmsd"):
        assert (out / f"{fig}.png").stat().st_size > 1000
