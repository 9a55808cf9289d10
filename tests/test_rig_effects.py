"""Undeclared effects in the virtual transducer cart (lss_fmu.rig_effects, issue 7):
the draws are reproducible, seed-dependent and inside their documented ranges
and the FMU's; a measurement with effects has the same meta.json as one without
while its truth records them; the channel_bump artefact changes one channel
near its place only; unknown names are refused with the known ones listed."""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pandas as pd
import pytest

from lss_fmu import measurement as M
from lss_fmu import rig
from lss_fmu import rig_effects as E
from lss_fmu.layouts import load_track
from lss_app.cli import main as lss


def rig_main(argv: list) -> int:
    return lss(["rig", *argv])
from lss_fmu.sensor import SensorModel
from lss_fmu.variables import BY_NAME, FORCE_CHANNELS

LAYOUTS = [lay for lay, _ in rig.MEASUREMENTS_PER_LAYOUT]


def _all_parameters():
    return sorted({p for n in E.CATALOGUE for p in E.PARAMETERS[n]})


# ------------------------------------------------------------------ no FMU needed

def test_catalogue_parameters_are_fmu_variables():
    missing = [p for p in _all_parameters() if p not in BY_NAME]
    if missing:
        pytest.skip(f"lss_fmu.variables has not got these effects parameters yet (issue 7): {missing}")
    for p in _all_parameters():
        v = BY_NAME[p]
        assert v.causality == "parameter" and v.variability == "fixed", p
    assert set(E.PARAMETERS) == set(E.CATALOGUE)
    assert E.CATALOGUE == ("wheel_oor", "track_bump", "joint_clearance", "motor_ripple", "resistance",
                           "sensor", "mass")
    assert E.ARTEFACT == "channel_bump" and E.ARTEFACT not in E.CATALOGUE


def test_draws_reproducible_and_seed_dependent():
    a = E.effects_truth("all", 7, "layout7", transducer=12, stream=7)
    assert a == E.effects_truth(list(E.CATALOGUE), 7, "layout7", transducer=12, stream=7)
    assert list(a) == list(E.CATALOGUE)
    b = E.effects_truth("all", 8, "layout7", transducer=12, stream=7)
    c = E.effects_truth("all", 7, "layout7", transducer=12, stream=6)    # another layout's stream
    for name in E.CATALOGUE:
        assert a[name]["parameters"] != b[name]["parameters"], name
        assert a[name]["parameters"] != c[name]["parameters"], name
    # an effect's draw does not depend on which others are requested
    for name in E.CATALOGUE:
        assert E.effects_truth([name], 7, "layout7", transducer=12, stream=7)[name] == a[name]
    flat = E.draw_effects("wheel_oor,sensor", 7, "layout7", transducer=12, stream=7)
    assert flat == {**a["wheel_oor"]["parameters"], **a["sensor"]["parameters"]}
    # artefacts likewise
    x = E.draw_artefacts(["channel_bump"], 7, 65.0, stream=7, avoid_s=23.0)
    assert x == E.draw_artefacts("channel_bump", 7, 65.0, stream=7, avoid_s=23.0)
    assert x != E.draw_artefacts(["channel_bump"], 8, 65.0, stream=7, avoid_s=23.0)


def _in(value, lo, hi, absolute=False):
    v = abs(value) if absolute else value
    return lo - 1e-12 <= v <= hi + 1e-12


def test_draws_within_documented_and_fmu_ranges():
    signs = {p: set() for p in E.ABS_RANGE}
    orders, n_channels = set(), set()
    for layout in LAYOUTS:
        track = load_track(layout)
        joints = [float(s) for s in track.s0]
        stretch = rig.NOMINAL_PRETENSION[layout] / track.n_carts
        for seed in range(40):
            t = E.effects_truth("all", seed, track, transducer=3, stream=rig._layout_index(layout))
            for name, d in t.items():
                assert set(d["parameters"]) <= set(E.PARAMETERS[name]), name
                for p, val in d["parameters"].items():
                    var = BY_NAME.get(p)
                    if var is None:
                        pytest.skip(f"the FMU variables have not got {p} yet (issue 7)")
                    assert isinstance(val, int if var.type == "Integer" else float), (p, val)
                    assert math.isfinite(val), p
                    if var.min is not None:
                        assert val >= var.min, (p, val, var.min)
                    if var.max is not None:
                        assert val <= var.max, (p, val, var.max)
                    if p in E.RANGES:
                        assert _in(val, *E.RANGES[p], absolute=p in E.ABS_RANGE), (p, val, E.RANGES[p])
                    if p in signs:
                        signs[p].add(val > 0)
            w = t["wheel_oor"]["parameters"]
            k = w["effects.wheel_oor.order"]
            orders.add(k)
            assert k in E.WHEEL_OOR_ORDERS and w["effects.wheel_oor.cart"] == -1
            assert _in(w["effects.wheel_oor.amplitude"] * k ** 2, *E.WHEEL_OOR_AMPLITUDE)
            assert t["wheel_oor"]["cart_index"] == 3
            b = t["track_bump"]["parameters"]
            assert b["effects.track_bump.s"] in joints and 0 <= b["effects.track_bump.s"] < track.length
            assert _in(abs(b["effects.track_bump.height"]), *E.TRACK_BUMP_HEIGHT)
            gap = t["joint_clearance"]["parameters"]["effects.joint_clearance.gap"]
            assert _in(gap / stretch, *E.JOINT_CLEARANCE_REL), (layout, gap, stretch)
            assert gap < stretch                       # the chain keeps its preload
            sens = t["sensor"]["parameters"]
            chans = t["sensor"]["channels"]
            n_channels.add(len(chans))
            assert E.SENSOR_N_CHANNELS[0] <= len(chans) <= E.SENSOR_N_CHANNELS[1]
            assert len(sens) == 2 * len(chans) and set(chans) <= set(FORCE_CHANNELS)
            for c, v in chans.items():
                short = c.removeprefix("transducer.")
                assert sens[f"effects.sensor.gain.{short}"] == v["gain"]
                assert sens[f"effects.sensor.offset.{short}"] == v["offset_N"]
    assert orders == set(E.WHEEL_OOR_ORDERS)
    assert n_channels == set(range(E.SENSOR_N_CHANNELS[0], E.SENSOR_N_CHANNELS[1] + 1))
    assert all(s == {True, False} for s in signs.values()), signs       # both signs occur
    # the documented ranges lie inside the FMU's
    for p, (lo, hi) in E.RANGES.items():
        var = BY_NAME[p]
        lo2 = -hi if p in E.ABS_RANGE else lo
        assert var.min is None or lo2 >= var.min, p
        assert var.max is None or hi <= var.max, p


def test_artefact_draws_within_ranges():
    L, s_M = 65.0, 23.0
    chans = set()
    for seed in range(200):
        a = E.draw_artefacts(["channel_bump"], seed, L, stream=7, avoid_s=s_M)["channel_bump"]
        chans.add(a["channel"])
        assert a["channel"] in FORCE_CHANNELS and a["sign"] in (-1, 1)
        assert _in(a["duration_s"], *E.ARTEFACT_DURATION)
        assert _in(a["relative_amplitude"], *E.ARTEFACT_REL_AMPLITUDE)
        assert 0 <= a["s"] < L
        gap = min(abs(a["s"] - s_M), L - abs(a["s"] - s_M))
        assert gap >= E.ARTEFACT_MARGIN_M - 1e-9, (seed, a["s"])
    assert chans == set(FORCE_CHANNELS)


def test_unknown_names_are_refused_with_the_known_ones(tmp_path, capsys):
    with pytest.raises(ValueError) as err:
        E.parse_effects("wheel_oor,wobble")
    msg = str(err.value)
    assert "'wobble'" in msg and all(n in msg for n in E.CATALOGUE)
    with pytest.raises(ValueError, match="known: wheel_oor, track_bump"):
        E.draw_effects(["mass", "gremlins"], 1, "layout7")
    with pytest.raises(ValueError, match="use --artefact"):
        E.parse_effects(["channel_bump"])
    with pytest.raises(ValueError, match=r"known: channel_bump"):
        E.parse_artefacts("sensor")
    with pytest.raises(ValueError, match="wobble"):
        rig.make_case("recovery", 20, effects=["wobble"])
    assert E.parse_effects("sensor, wheel_oor,sensor") == ["wheel_oor", "sensor"]
    assert E.parse_effects("all") == list(E.CATALOGUE) and E.parse_effects(None) == []
    # the command line
    out = str(tmp_path / "x")
    assert rig_main(["--set", "recovery", "--out", out, "--effects", "wheel_oor,wobble"]) == 2
    err = capsys.readouterr().err
    assert "unknown effect 'wobble'" in err and all(n in err for n in E.CATALOGUE)
    assert rig_main(["--set", "recovery", "--out", out, "--artefact", "loose_bolt"]) == 2
    assert "known: channel_bump" in capsys.readouterr().err
    assert rig_main(["--set", "recovery", "--out", out, "--effect-seed", "3"]) == 2
    assert "--effect-seed needs --effects" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_effects_change_only_fmu_parameters_and_truth_not_meta(tmp_path):
    """make_case with effects: the same draws of everything else, the effects'
    parameters added to the FMU's, the same meta.json; recovery and field share
    the effects, and the field set's bump sits on an as-built element joint
    whether or not the as-built file is written (so the staleness check agrees)."""
    sensor = SensorModel()
    for n in (1, 9, 20):
        a = rig.make_case("recovery", n)
        b = rig.make_case("recovery", n, effects="all", effect_seed=7, artefacts=["channel_bump"])
        assert (b.truth, b.cor, b.transducer, b.stop_time) == (a.truth, a.cor, a.transducer, a.stop_time)
        extra = {k: v for k, v in b.fmu_params.items() if k not in a.fmu_params}
        assert {k: b.fmu_params[k] for k in a.fmu_params} == a.fmu_params
        assert extra == {p: v for d in b.effects.values() for p, v in d["parameters"].items()}
        assert b.effect_seed == 7 and set(b.artefacts) == {"channel_bump"} and a.effects == {} == a.artefacts
        assert rig.meta_for(a, sensor, 100, True) == rig.meta_for(b, sensor, 100, True)
        assert "effect" not in json.dumps(rig.meta_for(b, sensor, 100, True)).lower()
        # without an effect seed the set's seed is used
        assert rig.make_case("recovery", n, effects=["mass"]).effect_seed == rig.DEFAULT_SEED
    f1 = rig.make_case("field", 22, effects=["track_bump", "joint_clearance"], effect_seed=3)
    f2 = rig.make_case("field", 22, answers_dir=tmp_path, effects=["track_bump", "joint_clearance"],
                       effect_seed=3)
    r = rig.make_case("recovery", 22, effects=["track_bump", "joint_clearance"], effect_seed=3)
    s_f = f1.fmu_params["effects.track_bump.s"]
    assert f2.fmu_params["effects.track_bump.s"] == s_f
    assert s_f in [float(s) for s in load_track(str(tmp_path / "tracks" / "layout7.layout")).s0]
    assert f1.effects["joint_clearance"] == r.effects["joint_clearance"]
    assert f1.effects["track_bump"]["joint_index"] == r.effects["track_bump"]["joint_index"]


def _record(L=65.0, v=2.0, s0=3.0, T=20.0, rate=1200.0):
    t = np.arange(int(T * rate) + 1) / rate
    data = {"time": t, "transducer.s": (s0 + v * t) % L}
    for j, c in enumerate(FORCE_CHANNELS):
        data[c] = 100.0 * (j + 1) + 300.0 * np.sin(2 * np.pi * (0.3 + 0.1 * j) * t)
    return pd.DataFrame(data)


def test_channel_bump_changes_one_channel_near_its_place():
    L, v, s0 = 65.0, 2.0, 3.0
    rec = _record(L, v, s0)
    art = {"channel": "transducer.joint.F_z", "s": 40.0, "duration_s": 0.2, "relative_amplitude": 0.1, "sign": -1}
    out, info = E.apply_channel_bump(rec, art, L, arm_time=4.0)
    t = rec["time"].to_numpy()
    # passages after arming: (40 - 3) / 2 = 18.5 s only (the next one would be at 51 s)
    assert info["centres_sim_s"] == pytest.approx([18.5], abs=1e-9)
    x = rec["transducer.joint.F_z"].to_numpy()
    sel = t >= 4.0
    rng_N = np.percentile(x[sel], 99) - np.percentile(x[sel], 1)
    assert info["amplitude_N"] == pytest.approx(-0.1 * rng_N)
    for c in rec.columns:
        if c != art["channel"]:
            assert np.array_equal(out[c].to_numpy(), rec[c].to_numpy()), c
    d = out[art["channel"]].to_numpy() - x
    assert np.all(d[np.abs(t - 18.5) >= 0.1] == 0.0)
    assert np.all(d[np.abs(t - 18.5) < 0.099] < 0.0)
    assert d.min() == pytest.approx(info["amplitude_N"], rel=1e-6)
    assert t[np.argmin(d)] == pytest.approx(18.5, abs=1 / 1200)
    assert rec is not out and np.array_equal(rec["transducer.joint.F_z"].to_numpy(), x)   # not in place
    # a quiet channel gets at least the floor range; every passage gets a pulse
    quiet = rec.copy()
    quiet["transducer.steering.F_right"] = 0.0
    art2 = dict(art, channel="transducer.steering.F_right", sign=1, s=10.0)
    out2, info2 = E.apply_channel_bump(quiet, art2, L, arm_time=0.0)
    assert info2["amplitude_N"] == pytest.approx(0.1 * E.ARTEFACT_RANGE_FLOOR_N)
    assert info2["centres_sim_s"] == pytest.approx([3.5], abs=1e-9)
    long = _record(L, v, s0, T=80.0)
    _, info3 = E.apply_channel_bump(long, art, L, arm_time=0.0)
    assert info3["centres_sim_s"] == pytest.approx([18.5, 18.5 + L / v], abs=1e-9)     # 18.5 + 2 L / v > 80 s


# ------------------------------------------------------------------ with the FMU

@pytest.fixture(scope="module")
def sim():
    from lss_fmu.runner import ChainSimulator
    with ChainSimulator() as s:
        yield s


def _fmu_has(names):
    from lss_fmu.runner import fmu_path
    lacks = E.fmu_lacks(fmu_path(), names)
    if lacks:
        pytest.skip(f"build/LSSChain.fmu has not got {', '.join(lacks)} yet (issue 7)")


def test_artefact_through_the_sensor_changes_one_channel_near_its_place(sim):
    """A short run of a layout-7 measurement with and without the artefact, placed in
    the middle of the logged window: only its channel differs, only around the
    passage, by about its amplitude (the 100 Hz filter passes a 0.1-0.3 s pulse)."""
    base = rig.make_case("recovery", 20, lap_seconds=1.5)
    case = rig.make_case("recovery", 20, lap_seconds=1.5, artefacts=["channel_bump"], effect_seed=5)
    art = dict(case.artefacts["channel_bump"])
    v = case.truth["v_s"]
    art["s"] = (case.truth["s_M"] + 0.75 * v) % case.track_length       # 0.75 s after the trigger
    case = dataclasses.replace(case, artefacts={"channel_bump": art})
    sensor = SensorModel()
    a, _, _ = rig.simulate_case(base, sim, sensor, 1.5)
    b, acq, _ = rig.simulate_case(case, sim, sensor, 1.5)
    info = acq["artefacts"]["channel_bump"]
    (tc,) = info["centres_since_trigger_s"]
    assert tc == pytest.approx(0.75, abs=0.05)
    c = art["channel"]
    for ch in a.columns:
        if ch != c:
            assert np.array_equal(a[ch].to_numpy(), b[ch].to_numpy()), ch
    t = a["time"].to_numpy()
    d = b[c].to_numpy() - a[c].to_numpy()
    half = art["duration_s"] / 2
    assert np.all(np.abs(d[(t < tc - half - 0.01) | (t > tc + half + 0.05)]) < 0.02)   # the filter's tail
    assert abs(d).max() == pytest.approx(abs(info["amplitude_N"]), rel=0.1)
    assert abs(t[np.argmax(abs(d))] - tc) < 0.02
    assert np.sign(d[np.argmax(abs(d))]) == art["sign"]


def test_measurement_with_effects_looks_like_any_other(tmp_path):
    """A short layout-7 measurement with every effect and the artefact, and without:
    meta.json and the files around it are the same, the samples are not, the
    truth records every effect and the artefact, and the staleness check tells
    the two apart."""
    _fmu_has(E.CATALOGUE)
    plain, hidden = tmp_path / "plain", tmp_path / "hidden"
    r = rig.generate_set("recovery", plain, [20], workers=1, lap_seconds=1.5, progress=False, log=lambda *_: None)
    assert "error" not in r[0], r[0]
    code = rig_main(["--set", "recovery", "--out", str(hidden), "--measurements", "20", "--workers", "1",
                     "--lap-seconds", "1.5", "--no-progress", "--effects", "all", "--effect-seed", "7",
                     "--artefact", "channel_bump"])
    assert code == 0
    ma, mb = M.load_measurement(plain / "m20"), M.load_measurement(hidden / "m20")
    assert ma.meta == mb.meta                                  # ids and dates included: nothing varies
    assert sorted(p.name for p in (hidden / "m20").iterdir()) == ["meta.json", "samples.csv"]
    for f in ("m20/meta.json", "m20/samples.csv", "set.json"):
        text = (hidden / f).read_text().lower()
        assert "effect" not in text and "artefact" not in text and "bump" not in text, f
    head = lambda p: [ln for ln in (p / "m20" / "samples.csv").read_text().splitlines() if ln.startswith("#")]  # noqa
    assert head(plain) == head(hidden)
    sa, sb = json.loads((plain / "set.json").read_text()), json.loads((hidden / "set.json").read_text())
    assert set(sa) == set(sb) and sa["description"] == sb["description"]
    # the effects act: every force channel differs
    for c in FORCE_CHANNELS:
        assert not np.allclose(ma.samples[c], mb.samples[c]), c
    # the truth
    t = rig.load_truth(hidden / "m20")
    case = rig.make_case("recovery", 20, effects="all", effect_seed=7, artefacts=["channel_bump"])
    assert t["effect_seed"] == 7 and list(t["effects"]) == list(E.CATALOGUE)
    for name in E.CATALOGUE:
        assert t["effects"][name]["parameters"] == case.effects[name]["parameters"], name
        for p, val in case.effects[name]["parameters"].items():
            assert t["fmu_parameters"][p] == val
    art = t["artefacts"]["channel_bump"]
    assert {k: v for k, v in art.items() if k != "applied"} == case.artefacts["channel_bump"]
    assert art["applied"]["channel"] == art["channel"] and art["applied"]["amplitude_N"] != 0
    t0 = rig.load_truth(plain / "m20")
    assert t0["effects"] == {} and t0["artefacts"] == {} and t0["effect_seed"] is None
    # staleness: other effects are another measurement
    fx = (tuple(E.CATALOGUE), 7, ("channel_bump",), "steady")
    for folder, truth in ((hidden, t), (plain, t0)):
        truth["full_lap"] = True
        (folder / "answers" / "m20" / "truth.json").write_text(json.dumps(truth))
    sha = t["fmu_sha256"]
    assert rig._existing(hidden, 20, "recovery", rig.DEFAULT_SEED, sha, fx) == ""
    assert rig._existing(plain, 20, "recovery", rig.DEFAULT_SEED, sha) == ""
    assert "other undeclared effects" in rig._existing(hidden, 20, "recovery", rig.DEFAULT_SEED, sha)
    assert "other undeclared effects" in rig._existing(plain, 20, "recovery", rig.DEFAULT_SEED, sha, fx)
    assert "other undeclared effects" in rig._existing(hidden, 20, "recovery", rig.DEFAULT_SEED, sha,
                                                       (("sensor",), 7, (), "steady"))
    assert "effect seed 7" in rig._existing(hidden, 20, "recovery", rig.DEFAULT_SEED, sha,
                                            (tuple(E.CATALOGUE), 8, ("channel_bump",), "steady"))
    with pytest.raises(FileExistsError, match="m20: it was made with other undeclared effects"):
        rig.generate_set("recovery", hidden, [20], workers=1, progress=False, log=lambda *_: None)
    # drawn parameters that changed (another version of the draws) are caught too
    t["effects"]["sensor"]["parameters"] = {k: v * 1.01 for k, v in t["effects"]["sensor"]["parameters"].items()}
    t["fmu_parameters"].update(t["effects"]["sensor"]["parameters"])
    (hidden / "answers" / "m20" / "truth.json").write_text(json.dumps(t))
    assert "effects.sensor." in rig._existing(hidden, 20, "recovery", rig.DEFAULT_SEED, sha, fx)


def test_a_benchmark_sets_an_effects_size_and_the_truth_says_so():
    """effect_values replace drawn values only: the phases, places and the
    transducer cart stay as drawn, the truth lists what was set, and a value of
    an effect not switched on is refused naming it."""
    drawn = rig.make_case("recovery", 5, effects=["wheel_oor"], effect_seed=4, protocol="start-stop",
                          lap_seconds=1.2)
    sized = rig.make_case("recovery", 5, effects=["wheel_oor"], effect_seed=4, protocol="start-stop",
                          lap_seconds=1.2, effect_values={"effects.wheel_oor.amplitude": 5e-5,
                                                          "effects.wheel_oor.order": 2})
    p0, p1 = drawn.effects["wheel_oor"]["parameters"], sized.effects["wheel_oor"]["parameters"]
    assert p1["effects.wheel_oor.amplitude"] == 5e-5 and p1["effects.wheel_oor.order"] == 2
    assert sized.fmu_params["effects.wheel_oor.amplitude"] == 5e-5
    for k in ("effects.wheel_oor.phase_left", "effects.wheel_oor.phase_right"):
        assert p1[k] == p0[k]
    assert sized.effects["wheel_oor"]["set"] == ["effects.wheel_oor.amplitude", "effects.wheel_oor.order"]
    assert sized.effects["wheel_oor"]["amplitude_times_order2_m"] == pytest.approx(2e-4)
    assert sized.transducer == drawn.transducer and "set" not in drawn.effects["wheel_oor"]
    with pytest.raises(ValueError, match="effects.motor_ripple.amplitude"):
        rig.make_case("recovery", 5, effects=["wheel_oor"], effect_seed=4,
                      effect_values={"effects.motor_ripple.amplitude": 50.0})
    with pytest.raises(ValueError, match="no effect is switched on"):
        rig.make_case("recovery", 5, effect_values={"effects.wheel_oor.amplitude": 5e-5})
