"""Identification against known ground truth (issue 6).

The chain is chaotic in steady running (docs/identification.md): a change of
a CoR by 0.003 or a tenfold tighter solver tolerance decorrelates the forces
within seconds, so the pointwise NRMSD of the paper cannot resolve CoRs to
+-0.03 there. In a transient, the release of the assembled chain, damping
shapes the response before chaos grows, and the CoRs are identifiable; the
recovery test uses that window of a layout-7 run with the sensor's noise. The
radial joint CoR moves the forces less than the sensor noise does: its
profile shows it instead of a loosened recovery test.
"""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from identification.pipeline.identify import identify
from identification.objective.problem import DESIGN, IdentificationProblem
from identification.pipeline.profile import noise_floor, profile
from lss_fmu.variables import FORCE_CHANNELS

CORS = DESIGN[:4]
TRUTH = {"contact.e_JA": 0.46, "contact.e_JR": 0.558, "contact.e_SW": 0.351, "contact.e_RW": 0.645,
         "drive.v_ref": 2.0, "chain.pretension": 0.03, "wheel.mu_roll": 0.015, "trigger.s_M": 0.3,
         "drive.Kp": 500.0, "drive.Ki": 200.0}
FIXED = {"track.guide_gap": -0.0003}


@pytest.fixture(scope="module")
def release_problem(fmu_file):
    """Layout 7, LW, the first 0.6 s after the trigger right behind the
    start: the measurement is the model at the truth (Table 3, row 1) plus
    the sensor model's noise (identification.loop.synthetic)."""
    from identification.loop.synthetic import release_problem as make
    return make()


@pytest.mark.slow   # make test: the default pipeline's recovery, tests/test_front_door.py
def test_recovery_from_the_release_transient(release_problem):
    """Complex-RF with restarts (identify(restarts=...)) recovers e_JA, e_SW and
    e_RW within +-0.03 and drives f to the noise floor f(truth); e_JR is below
    the noise (next test)."""
    truth = np.array([TRUTH[k] for k in CORS])
    f_truth = release_problem(truth)
    res = identify(release_problem, max_evals=1000, seed=0, progress=False, restarts=3)
    err = dict(zip(CORS, res.x - truth))
    for k in ("contact.e_JA", "contact.e_SW", "contact.e_RW"):
        assert abs(err[k]) <= 0.03, (k, err)
    assert res.nfev <= 1000
    # the method as published stops on its parameter spread at ~20x the floor (726
    # evaluations with one seed); the restarts take it to within 2x
    assert res.f < 2.5 * f_truth, (res.f, f_truth)


def test_radial_joint_cor_is_below_the_noise(release_problem):
    """e_JR: over +-0.1 around the truth the objective rises by less than the
    noise floor f(truth); e_SW, for comparison, rises tenfold above it."""
    truth = np.array([TRUTH[k] for k in CORS])
    f_truth = release_problem(truth)
    jr = profile(release_problem, "contact.e_JR", [0.458, 0.658], truth)
    sw = profile(release_problem, "contact.e_SW", [0.251, 0.451], truth)
    assert np.max(jr.f) - f_truth < f_truth
    assert np.min(sw.f) - f_truth > 10 * f_truth


def test_objective_is_zero_at_the_truth_without_noise(release_problem):
    p = IdentificationProblem(release_problem.simulate([TRUTH[k] for k in CORS]), release_problem.times,
                              "layout7", "LW", release_problem.bounds, fixed=FIXED, free=CORS,
                              x0=release_problem.x0, settle=0.02)
    assert p([TRUTH[k] for k in CORS]) < 1e-20
    floor = noise_floor(p, [TRUTH[k] for k in CORS], n=2, scale=1e-6)
    assert np.all(floor < 1e-4)


def test_interrupted_identification_resumes_without_losing_evaluations(release_problem, tmp_path):
    journal = tmp_path / "journal.jsonl"
    full = identify(release_problem, max_evals=14, seed=3, progress=False, journal=tmp_path / "full.jsonl")
    identify(release_problem, max_evals=14, seed=3, progress=False, journal=journal)
    lines = journal.read_text().splitlines()
    # killed while writing line 8: 7 whole lines survive, the 8th is cut
    journal.write_text("\n".join(lines[:7]) + "\n" + lines[7][: len(lines[7]) // 2])
    again = identify(release_problem, max_evals=14, seed=3, progress=False, journal=journal)
    assert np.array_equal(again.x, full.x) and again.f == full.f
    assert again.replayed >= 7
    assert again.evaluated == full.evaluated - 7
    keys = [json.loads(ln)["k"] for ln in journal.read_text().splitlines()[:7]]
    assert len(set(keys)) == 7


def test_bad_bounds_and_unknown_model_are_refused():
    t = np.arange(0, 0.1, 1 / 300)
    with pytest.raises(ValueError, match="unknown contact model 'XY'"):
        IdentificationProblem(np.zeros((len(t), 7)), t, "layout7", "XY", {k: (0.2, 0.9) for k in CORS}, free=CORS)
    with pytest.raises(ValueError, match="impossible bounds for contact.e_SW"):
        IdentificationProblem(np.zeros((len(t), 7)), t, "layout7", "LW",
                              {**{k: (0.2, 0.9) for k in CORS}, "contact.e_SW": (0.9, 0.2)}, free=CORS)


def test_failed_simulation_is_a_bad_value_not_a_crash(release_problem, caplog):
    p = IdentificationProblem(release_problem.samples, release_problem.times, "no_such_layout", "LW",
                              release_problem.bounds, free=CORS, x0=release_problem.x0, settle=0.02)
    assert p([0.5] * 4) == 100.0
    assert "no_such_layout" in caplog.text


def test_identify_command_end_to_end(fmu_file, tmp_path):
    """`lss identify` on a measurement folder: result JSON (with the settings
    used) and the figures."""
    from lss_app.cli import main
    from lss_fmu.measurement import write_measurement
    p_times = np.arange(0, 0.5, 1 / 300)
    p = IdentificationProblem(np.zeros((len(p_times), 7)), p_times, "layout7", "LW",
                              {k: (0.2, 0.9) for k in CORS}, free=CORS, x0=TRUTH, settle=3.0)
    from lss_fmu.runner import LazySimulator
    from lss_fmu.triggered import simulate_triggered
    from lss_fmu.variables import SPEED_CHANNELS
    params, s_m = p.fmu_params([TRUTH[k] for k in CORS])
    sig = simulate_triggered(LazySimulator()(), params, s_m, p_times, settle=3.0,
                             channels=FORCE_CHANNELS + SPEED_CHANNELS)
    df = pd.DataFrame(sig, columns=FORCE_CHANNELS + SPEED_CHANNELS)
    df.insert(0, "time", p_times)
    meta = {"format_version": 1, "id": "t01", "layout": "layout7", "wheel_type": "C", "coupling_type": "A",
            "speed_nominal": 2.0, "pretension_nominal": 0.03, "sample_rate": 300.0, "trigger_point": 0.3,
            "date": "2026-11-22"}
    df[FORCE_CHANNELS + SPEED_CHANNELS] = df[FORCE_CHANNELS + SPEED_CHANNELS].round(3)
    write_measurement(tmp_path / "m", df, meta)
    out = tmp_path / "out"
    settings = tmp_path / "quick.toml"
    settings.write_text('[identify]\nsteady_evals = 8\nfree = ["e_SW", "e_RW"]\n')
    rc = main(["identify", str(tmp_path / "m"), "--model", "LW", "--out", str(out), "--settings", str(settings),
               "--no-progress"])
    assert rc == 0
    res = json.loads((out / "result.json").read_text())
    assert res["model"] == "LW" and res["nfev"] >= 8 and set(res["x"]) == {"contact.e_SW", "contact.e_RW"}
    assert res["f"] <= res["f0"]
    # a record of steady running: the statistics, and the CoRs said to be out of its reach
    assert res["method"] == "statistics" and "not identifiable" in res["message"]
    assert res["settings"]["steady_evals"] == 8 and res["settings"]["free"] == ["e_SW", "e_RW"]
    for fig in ("forces", "history", "nrmsd"):
        assert (out / f"{fig}.png").stat().st_size > 1000
    assert main(["identify", str(tmp_path / "m"), "--model", "XX", "--out", str(out)]) == 2
    assert main(["identify", str(tmp_path / "missing"), "--model", "LW", "--out", str(out)]) == 2
