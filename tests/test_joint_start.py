"""Where a joint identification starts (identification.joint_start, issue 17):
the first record alone, then each further record's trigger point scanned on
its first window."""
from __future__ import annotations

import numpy as np
import pytest

from identification import growing
from identification.joint import JointProblem, own
from identification.joint_start import single_start, trigger_scan
from identification.problem import from_measurement, weighted_residual
from identification.windowing import truncated
from lss_fmu.design import TRIGGER
from lss_fmu.rig import load_truth, true_design_values

NUMBER, SECONDS, WINDOW = 2, 1.2, 0.6   # layout 1: a start-stop (its stop at 1 s), the first 0.6 s


@pytest.fixture(scope="module")
def two_records(tmp_path_factory, fmu_file):
    from lss_fmu import measurement as M
    from lss_fmu.rig import folder_name, run_measurement
    from lss_fmu.runner import ChainSimulator
    out = []
    for k in range(2):
        folder = tmp_path_factory.mktemp(f"joint_start_r{k}")
        with ChainSimulator() as s:
            run_measurement("recovery", NUMBER, folder, s, protocol="start-stop", lap_seconds=SECONDS, repeat=k)
        out.append(M.load_measurement(folder / folder_name(NUMBER)))
    return out


def _joint(records):
    parts = [from_measurement(r, "LW", window=WINDOW, tare=True, objective="likelihood") for r in records]
    truth = [true_design_values(load_truth(r)) for r in records]
    return JointProblem(parts), truth


def test_the_trigger_scan_finds_a_records_trigger_point(two_records):
    jp, truth = _joint(two_records)
    part = jp.parts[1]
    w = 1.0 / np.asarray(part.noise, float) ** 2
    lo, hi = part.bounds[TRIGGER]
    s, S, used = trigger_scan(part, truth[0], w, 0.3)   # the shared values as they are, its own trigger not
    assert used == 52 and lo <= s <= hi
    assert abs(s - truth[1][TRIGGER]) < 0.01, (s, truth[1][TRIGGER])
    x_true = np.array([truth[1][n] for n in part.free])
    q = truncated(part, part.times[0] + 0.3)
    S_true = weighted_residual(q, q.simulate(x_true), w)[1] / q.samples.size
    assert S <= S_true * 1.02   # at least as good as the truth's trigger point, to the fine grid's step


def test_a_start_given_skips_the_complex(two_records, monkeypatch):
    jp, truth = _joint(two_records)
    x_true = np.array([{**truth[0], own(1): truth[1][TRIGGER]}[n] for n in jp.free])

    def no_complex(*a, **k):
        raise AssertionError("the complex ran although a start was given")
    monkeypatch.setattr(growing, "identify", no_complex)
    w = 1.0 / np.asarray(jp.noise, float) ** 2
    x, info = growing.grow(jp, start=x_true, channel_weights=w, reset_unseen=True)
    assert not info["unseen"]                                   # nothing reset: the start is not random
    assert all(t["S_per_sample"] < 1.3 for t in info["windows"])   # at the noise on every window
    k = [jp.free.index(f"contact.{c}") for c in ("e_JA", "e_SW", "e_RW")]   # e_JR: not identifiable here
    assert np.allclose(x[k], x_true[k], atol=0.03)               # the CoRs stay where the truth put them


def test_the_single_start_is_the_first_record_and_the_others_triggers(two_records):
    jp, truth = _joint(two_records)
    w = 1.0 / np.asarray(jp.noise, float) ** 2
    x, info = single_start(jp, w, evals=40, first=0.3, seed=1, profile_points=0)
    vals = jp.values(x)
    assert [t["record"] for t in info["triggers"]] == [1]
    assert vals[own(1)] == info["triggers"][0]["trigger"]
    assert info["single"][-1]["window_s"] == pytest.approx(WINDOW, abs=0.01)
    assert info["nfev"] > 40 + 52
    # the scan with the first record's values, as found, puts the second record's trigger near its truth
    assert abs(vals[own(1)] - truth[1][TRIGGER]) < 0.05
