"""The virtual transducer cart: the trigger lines up runs from different
starting positions, the test plan is reproducible from the seed, and a small
rig run (shortened logs on layout 7) writes loadable measurement folders with
the truth kept apart."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from lss_fmu import design
from lss_fmu import measurement as M
from lss_fmu import rig, sensor as S
from lss_fmu.layouts import load_track
from lss_app.cli import main as lss


def rig_main(argv: list) -> int:
    return lss(["rig", *argv])
from lss_fmu.variables import FORCE_CHANNELS


# ------------------------------------------------------------------ no FMU needed

def test_numbering_and_plan():
    assert [sum(1 for v in rig.NUMBERING.values() if v == lay) for lay, _ in rig.MEASUREMENTS_PER_LAYOUT] \
        == [4, 4, 3, 1, 6, 1, 3]
    assert rig.NUMBERING[1] == "layout1" and rig.NUMBERING[13] == "layout5" and rig.NUMBERING[22] == "layout7"
    assert len(rig.TABLE3) == 22 and set(rig.TEST_PLAN) == set(range(1, 23))
    assert all(1.5 <= v <= 3.0 for v, _ in rig.TEST_PLAN.values())
    assert rig.parse_numbers("1,2,19-22") == [1, 2, 19, 20, 21, 22]
    assert rig.parse_numbers(None) == list(range(1, 23))
    for bad in ("0", "23", "3-1", "x", "1,,2"):
        with pytest.raises(ValueError, match="--measurements"):
            rig.parse_numbers(bad)


def test_cases_reproducible_and_within_bounds():
    for n in range(1, 23):
        a = rig.make_case("recovery", n)
        assert a == rig.make_case("recovery", n)                       # same seed, same draw
        f = rig.make_case("field", n)
        assert f.truth == a.truth and f.cor == a.cor                   # the sets share the draws
        assert f.contact_law == "GZ" and a.contact_law == "LW"
        assert a.fmu_params["contact.model"] == 3 and f.fmu_params["contact.model"] == 5
        assert tuple(a.cor[k] for k in rig.COR_NAMES) == rig.TABLE3[n - 1]
        assert rig.make_case("recovery", n, seed=5).truth != a.truth   # another seed, other draws
        meta = {"speed_nominal": a.speed_nominal, "pretension_nominal": a.pretension_nominal,
                "trigger_point": a.s_M_nominal}
        dv = design.bounds_from_meta(meta)
        for k, val in a.truth.items():
            assert dv[k]["lower"] < val < dv[k]["upper"], (n, k, val, dv[k])
        # the transducer cart reaches s_M after the settle time and before the end
        assert rig.SETTLE_TIME < a.arrival_time < rig.SETTLE_TIME + 3.0
        assert a.stop_time > a.arrival_time + a.track_length / a.truth["v_s"]
        assert 0 <= a.transducer < a.n_carts
        assert "cart.mass_factor" not in a.fmu_params and "track.guide_gap" not in a.fmu_params
        assert 0.95 <= f.fmu_params["cart.mass_factor"] <= 1.05


def test_drawn_set_draws_every_cor_over_the_box_and_nothing_else():
    lo, hi = design.COR_BOUNDS
    drawn = []
    for n in range(1, 23):
        a, d = rig.make_case("recovery", n), rig.make_case("drawn", n)
        assert d == rig.make_case("drawn", n)                          # same seed, same draw
        assert d.truth == a.truth and d.contact_law == "LW"             # only the contacts differ
        assert all(lo <= d.cor[k] <= hi for k in rig.COR_NAMES)
        assert {k: d.fmu_params[f"contact.{k}"] for k in rig.COR_NAMES} == d.cor
        assert tuple(d.cor[k] for k in rig.COR_NAMES) != rig.TABLE3[n - 1]
        assert rig.make_case("drawn", n, seed=5).cor != d.cor           # another seed, other contacts
        drawn += list(d.cor.values())
    # 88 draws over the box: they fill it (a uniform draw leaves each quarter empty with p < 1e-10)
    quarters = np.histogram(drawn, bins=4, range=(lo, hi))[0]
    assert quarters.min() >= 10, quarters


def test_as_built_track_closes_and_differs_slightly(tmp_path):
    path, desc, spec = rig._as_built_track("layout5", 11, tmp_path)
    t, t0 = load_track(str(path)), load_track("layout5")
    assert t.closure_error < 1e-6 and abs(t.length - t0.length) < 1e-6 and t.n_carts == t0.n_carts
    assert 0 < desc["max_straight_change_m"] < 0.2 and 0 < desc["max_radius_change_m"] < 1.0


def test_cli_usage_errors(tmp_path, capsys):
    assert rig_main(["--set", "recovery", "--out", str(tmp_path), "--measurements", "30"]) == 2
    assert "no measurement 30" in capsys.readouterr().err
    assert rig_main(["--set", "lab", "--out", str(tmp_path)]) == 2
    assert rig_main(["--set", "field", "--out", str(tmp_path), "--workers", "0"]) == 2
    assert rig_main(["--set", "field"]) == 2


# ------------------------------------------------------------------ with the FMU

@pytest.fixture(scope="module")
def sim():
    from lss_fmu.runner import ChainSimulator
    with ChainSimulator() as s:
        yield s


def test_trigger_lines_up_different_starting_positions(sim):
    """Two runs of layout 7 whose transducer carts start at different places
    (they reach the trigger point 2 s apart) give the same signals once both
    are cut at the trigger (3 s into the 180 deg curve); cut at the same time
    instead, they do not."""
    L, v, s_M, n = 65.0, 2.0, 23.0, 900
    pitch = L / 52
    wins, recs = [], []
    for arrival in (4.6, 6.6):
        idx = int(round(((s_M - v * arrival) % L) / pitch)) % 52
        rec = sim.simulate(arrival + n / 300 + 1.0, step=1 / 300,
                           params={"layout.name": "layout7", "chain.transducer": idx,
                                   "chain.pretension": 0.023, "drive.v_ref": v})
        wins.append(S.trigger_window(rec, s_M, L, n, arm_time=rig.SETTLE_TIME))
        recs.append(rec)
    a, b = (w[FORCE_CHANNELS].to_numpy() for w in wins)
    span = a.max(axis=0) - a.min(axis=0)
    nrmsd = np.sqrt(((a - b) ** 2).mean(axis=0)) / span
    assert wins[1].attrs["trigger_time"] - wins[0].attrs["trigger_time"] > 1.5
    for j, c in enumerate(FORCE_CHANNELS):
        limit = 0.25 if c == "transducer.steering.F_right" else 0.06   # its sparse impacts vary
        assert nrmsd[j] < limit, (c, nrmsd[j])
    # without the trigger: the same absolute times of the two runs
    t0 = wins[0].attrs["trigger_time"]
    same_t = [r[(r.time >= t0 - 1e-9)].iloc[:n][FORCE_CHANNELS].to_numpy() for r in recs]
    nrmsd_t = np.sqrt(((same_t[0] - same_t[1]) ** 2).mean(axis=0)) / span
    assert nrmsd_t[1] > 4 * nrmsd[1] and nrmsd_t[3] > 4 * nrmsd[3]   # F_y and the left steering wheel


def test_small_recovery_run_is_loadable(tmp_path, capsys):
    out = tmp_path / "recovery"
    code = rig_main(["--set", "recovery", "--out", str(out), "--measurements", "20", "--workers", "1",
                     "--lap-seconds", "1.5", "--no-progress"])
    assert code == 0, capsys.readouterr().err
    m = M.load_measurement(out / "m20")
    assert m.n_samples == 450 and m.sample_rate == 300 and m.meta["layout"] == "layout7"
    assert m.meta["number"] == 20 and "shortened" in m.meta["notes"]
    assert np.isfinite(m.samples.to_numpy()).all()
    # forces are plausible: tension in the joint, the cart's weight on its wheels
    assert 200 < m.forces["transducer.joint.F_x"].mean() < 2500
    assert 100 < m.forces["transducer.driving.F_left"].mean() < 300
    # the truth is apart, complete, and not in the measurement folder
    assert sorted(p.name for p in (out / "m20").iterdir()) == ["meta.json", "samples.csv"]
    truth = rig.load_truth(out / "m20")
    assert truth["contact_law"] == "LW" and truth["cor"]["e_JA"] == rig.TABLE3[19][0]
    assert len(truth["x"]) == 10 and truth["n_samples"] == 450
    names, nom, lo, hi = m.bounds()
    x = np.array([truth["design_variables"][k] for k in names])
    assert np.all(lo < x) and np.all(x < hi)
    assert json.loads((out / "set.json").read_text())["measurements"]["m20"]["n_samples"] == 450
    # a partial run is not silently kept as a finished measurement
    with pytest.raises(FileExistsError, match="m20: it is a shortened run"):
        rig.generate_set("recovery", out, [20], workers=1, progress=False, log=lambda *_: None)
    # nor is a measurement made with another FMU or other parameters mixed into a set
    tfile = out / "answers" / "m20" / "truth.json"
    t = json.loads(tfile.read_text())
    sha = t["fmu_sha256"]
    assert rig._existing(out, 20, "recovery", rig.DEFAULT_SEED, sha) == "it is a shortened run (--lap-seconds)"
    # a shortened run of the length asked again is the same run; of another length it is not
    assert rig._existing(out, 20, "recovery", rig.DEFAULT_SEED, sha, lap_seconds=1.5) == ""
    assert rig._existing(out, 20, "recovery", rig.DEFAULT_SEED, sha, lap_seconds=1.0) == \
        "it is 450 samples long, not the 300 of --lap-seconds 1"
    t["full_lap"] = True
    tfile.write_text(json.dumps(t))
    assert rig._existing(out, 20, "recovery", rig.DEFAULT_SEED, sha) == ""
    assert "another FMU" in rig._existing(out, 20, "recovery", rig.DEFAULT_SEED, "0" * 64)
    assert "seed 20120901" in rig._existing(out, 20, "recovery", 1, sha)
    t["fmu_parameters"]["chain.pretension"] *= 1.1
    tfile.write_text(json.dumps(t))
    assert "chain.pretension" in rig._existing(out, 20, "recovery", rig.DEFAULT_SEED, sha)


def test_small_field_run(tmp_path):
    out = tmp_path / "field"
    res = rig.generate_set("field", out, [22], workers=1, lap_seconds=1.0, progress=False, log=lambda *_: None)
    assert "error" not in res[0], res[0]
    m = M.load_measurement(out / "m22")
    assert m.meta["layout"] == "layout7" and m.n_samples == 300     # the drawing, not the as-built track
    truth = rig.load_truth(out / "m22")
    assert truth["contact_law"] == "GZ" and truth["contact_model"] == 5
    assert truth["fmu_parameters"]["layout.name"].endswith("answers/tracks/layout7.layout")
    assert load_track(str(out / truth["layout_fmu"])).closure_error < 1e-6
    assert not math.isclose(truth["field_deviations"]["cart.mass_factor"], 1.0)
    assert M.find_measurements(out) == [out / "m22"]


def test_field_start_stop_resumes(tmp_path):
    """A field-set record from rest is kept by a second run: the relax time it was
    made with comes from the as-built track's length, not the design's."""
    out = tmp_path / "field"
    rig.generate_set("field", out, [21], workers=1, protocol="start-stop", progress=False, log=lambda *_: None)
    t = rig.load_truth(out / "m21")
    sha = t["fmu_sha256"]
    assert t["fmu_parameters"]["chain.relax_time"] == rig.rig_protocol("start-stop", 1.5).relax_time(
        load_track(str(out / t["layout_fmu"])).length)
    assert rig._existing(out, 21, "field", rig.DEFAULT_SEED, sha, ((), None, (), "start-stop", 0)) == ""
    res = rig.generate_set("field", out, [21], workers=1, protocol="start-stop", progress=False,
                           log=lambda *_: None, fmu=next((out / "fmu").glob("*.fmu")))
    assert "error" not in res[0], res[0]


def _add_to_set(args):
    out, number = args
    fmu = out / "fmu" / "lss.fmu"
    result = {"number": number, "layout": "layout1", "n_samples": 10, "full_lap": False, "wall_s": 0.0,
              "cpu_s": 0.0, "simulated_time_s": 0.0, "cart_seconds_per_cpu_second": 0.0}
    for _ in range(100):
        rig._write_set_json(out, "recovery", 1, "sha", fmu, [result])


def test_set_index_written_by_two_processes_keeps_both(tmp_path):
    """Two runs adding measurements to one set's folder at once (bench_recovery
    on two measurements): set.json is a read-modify-write; neither may fail on
    the other's temporary file nor drop its entries."""
    from concurrent.futures import ProcessPoolExecutor
    (tmp_path / "fmu").mkdir()
    with ProcessPoolExecutor(2) as pool:
        list(pool.map(_add_to_set, [(tmp_path, 8), (tmp_path, 18)]))
    entries = json.loads((tmp_path / "set.json").read_text())["measurements"]
    assert sorted(entries) == [rig.folder_name(8), rig.folder_name(18)]
    assert not list(tmp_path.glob("*.tmp"))
