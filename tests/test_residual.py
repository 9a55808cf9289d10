"""Residual analysis (identification/residual.py) on synthetic residuals whose
answer is known: no FMU, so these are fast."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from identification.loop.residual import (LINE_SNR_THRESHOLD, UNEVEN_RATIO, ResidualAnalysis, analyse_residual,
                                     describe, to_json)
from lss_fmu.layouts import load_track
from lss_fmu.variables import FORCE_CHANNELS

FS, V, S_START = 300.0, 2.0, 20.0
R7 = 0.045   # m: layout 7's driving wheels (type C), the FMU's cart.r_drive (tests/test_effects_fmu.py)


@pytest.fixture(scope="module")
def track7():
    return load_track("layout7")


def record(duration, seed=0, s_start=S_START, sigma=2.0):
    """Times, continuous s at 2 m/s, a measured signal with some span, white residual noise."""
    t = np.arange(int(round(duration * FS))) / FS
    s = s_start + V * t
    rng = np.random.default_rng(seed)
    measured = 1000.0 + 300.0 * np.sin(2 * np.pi * s[:, None] / 6.5 + np.arange(7)) + rng.normal(0, 5, (len(t), 7))
    noise = rng.normal(0.0, sigma, (len(t), 7))
    return t, s, measured, noise


def analyse(t, s, measured, residual, L, **kw):
    kw.setdefault("layout", "layout7")
    kw.setdefault("r_drive", R7)
    return analyse_residual(measured, measured - residual, t, s, L, **kw)


def circular_distance(a, b, L):
    d = abs(a - b) % L
    return min(d, L - d)


# ----------------------------------------------------------------------------- the basics
def test_nrmsd_span_offset_and_named_lines(track7):
    t, s, M, noise = record(5.0)
    R = noise.copy()
    R[:, 0] += 30.0
    a = analyse(t, s, M, R, track7.length)
    assert isinstance(a, ResidualAnalysis)
    assert a.channels == list(FORCE_CHANNELS)
    assert a.residual.shape == (len(t), 7) and np.allclose(a.residual, R)
    span = M.max(axis=0) - M.min(axis=0)
    assert np.allclose(a.span, span)
    assert np.allclose(a.nrmsd, np.sqrt(np.mean(R ** 2, axis=0)) / span)
    # the constant offset is reported as such, and kept out of the spectrum
    assert a.offset[0] == pytest.approx(30.0, abs=0.5)
    assert a.offset_share[0] > 0.98 and np.all(a.offset_share[1:] < 0.05)
    assert "offset of +30" in a.concentration["sentence"]
    for ln in a.orders["lines"].values():
        if ln["resolved"]:
            assert ln["line_snr"][0] < LINE_SNR_THRESHOLD
    # named lines of layout 7: wheel C (r_d = 45 mm), pitch 65 m / 52 carts, 7 motors
    assert a.orders["named"]["wheel"] == pytest.approx(1 / (2 * math.pi * 0.045))
    assert a.orders["named"]["cart"] == pytest.approx(52 / 65.0)
    assert a.orders["named"]["motor"] == pytest.approx(7 / 65.0)
    assert a.orders["resolution"] == pytest.approx(1 / (V * 5.0), rel=0.01)


def test_motor_presence_follows_the_reaction_plate(track7):
    m0, m1 = track7.motors[0]
    centre = 0.5 * (m0 + m1)
    # plate centre = axle - 0.40 m; the plate (one pitch long) overlaps the motor or not
    s_in = np.linspace(centre + 0.40 - 0.3, centre + 0.40 + 0.3, 40)
    s_out = np.linspace(centre + 0.40 + 1.3, centre + 0.40 + 2.5, 40)
    t = np.arange(80) / FS
    s = np.concatenate([s_in, s_out])
    M = np.random.default_rng(1).normal(0, 1, (80, 7))
    a = analyse_residual(M, M, t, s, track7.length, layout=track7)
    assert np.all(a.track["motor"][:40] == 1.0) and np.all(a.track["motor"][40:] == 0.0)


# ----------------------------------------------------------------------------- order lines
@pytest.mark.parametrize("duration", [0.6, 0.75, 1.0, 20.0])
def test_wheel_order_sinusoid_is_the_strongest_line(track7, duration):
    t, s, M, noise = record(duration, seed=3)
    f_wheel = 1 / (2 * math.pi * R7)
    R = noise.copy()
    R[:, 3] += 40.0 * np.sin(2 * np.pi * f_wheel * s + 0.7)
    # and a big component at the cart order, too slow to be resolved in a short record
    R[:, 5] += 30.0 * np.sin(2 * np.pi * 0.8 * s)
    a = analyse(t, s, M, R, track7.length)
    wheel = a.orders["lines"]["wheel"]
    assert wheel["resolved"]
    assert int(np.argmax(wheel["line_snr"])) == 3
    assert wheel["line_snr"][3] > 20
    assert wheel["amplitude"][3] == pytest.approx(40.0, rel=0.1)   # Hann coherent gain corrected
    others = [j for j in range(7) if j not in (3, 5)]
    assert np.all(wheel["line_snr"][others] < LINE_SNR_THRESHOLD)
    # on channel 3 no other resolved named line beats it
    for name, ln in a.orders["lines"].items():
        if name != "wheel" and ln["resolved"]:
            assert ln["line_snr"][3] < wheel["line_snr"][3]
    if duration < 2:
        assert not a.orders["lines"]["cart"]["resolved"]
    c = a.concentration
    assert c["line"]["name"] == "wheel" and c["line"]["channel"] == FORCE_CHANNELS[3] and c["line"]["significant"]
    assert c["channel"] == FORCE_CHANNELS[3]
    assert c["line_on_channel"]["name"] == "wheel"
    assert "wheel order" in c["sentence"] and FORCE_CHANNELS[3] in c["sentence"]


@pytest.mark.parametrize("duration", [0.6, 1.0, 40.0])
def test_white_noise_has_no_line_and_no_concentration(track7, duration):
    for seed in range(4):
        t, s, M, noise = record(duration, seed=10 + seed)
        a = analyse(t, s, M, noise, track7.length)
        snrs = [ln["line_snr"] for ln in a.orders["lines"].values() if ln["resolved"]]
        assert snrs, "at least the wheel line is resolved"
        assert np.max(snrs) < LINE_SNR_THRESHOLD
        c = a.concentration
        assert not c["line"]["significant"]
        st = c["stretch"]
        assert st["pattern"] == "spread" and st["ratio"] < UNEVEN_RATIO and not st["localised"]
        assert "spread along the track" in c["sentence"] and "No named order line" in c["sentence"]
        for name, sig in a.signals.items():
            if not sig["constant"]:
                assert np.all(sig["eta2_adj"] < 0.05), name


# ----------------------------------------------------------------------------- where on the track
@pytest.mark.parametrize("duration, s0", [(40.0, 30.0), (40.0, 64.7), (1.0, 20.9), (1.5, 22.1)])
def test_localised_pulse_is_located(track7, duration, s0):
    L = track7.length
    t, s, M, noise = record(duration, seed=5)
    R = noise.copy()
    d = (np.mod(s - s0 + 0.5 * L, L) - 0.5 * L)
    R[:, 2] += 250.0 * np.exp(-0.5 * (d / 0.05) ** 2)
    a = analyse(t, s, M, R, L)
    c = a.concentration
    assert c["channel"] == FORCE_CHANNELS[2]
    st = c["stretch"]
    w = st["width"]
    assert st["pattern"] == "localised" and st["share"] > 0.8
    assert circular_distance(st["centre"], s0, L) <= 0.5 * w
    assert circular_distance(0.5 * (st["start"] + st["end"]), s0, L) <= 0.15 * w   # centred on the pulse
    if duration < 2:
        assert st["window_shrunk"] and w == pytest.approx((s[-1] - s[0]) / 4)
    else:
        assert w == pytest.approx(2.0)
    # the fold puts the largest RMS within one bin of s0
    fo = a.fold
    k = int(np.nanargmax(fo["rms"][:, 2]))
    assert circular_distance(fo["centre"][k], s0, L) <= fo["bin_width"]
    assert f"{st['start']:.2f}" in c["sentence"]


def test_densest_window_is_not_where_the_record_passes_twice(track7):
    """1.5 laps: the first half lap is seen twice. A stretch where the residual's
    mean square is 1.6 times larger, seen once, must win over twice-seen plain noise."""
    L = track7.length
    t, s, M, noise = record(1.5 * L / V, seed=6, s_start=0.0)
    s0 = 45.0                                   # seen once (the record covers 0..97.5 m)
    inside = np.abs(np.mod(s, L) - s0) < 1.5
    R = noise * np.where(inside, math.sqrt(1.6), 1.0)[:, None]
    a = analyse(t, s, M, R, L)
    st = a.concentration["stretch"]
    assert circular_distance(st["centre"], s0, L) <= 0.5 * st["width"]
    assert st["ratio"] > 1.3 and st["sample_share"] == pytest.approx(st["width"] / (1.5 * L), rel=0.05)


def test_residual_proportional_to_curvature(track7):
    L = track7.length
    t, s, M, noise = record(40.0, seed=7)
    R = noise.copy()
    R[:, 1] += 300.0 * track7.curvature(s)[0]
    a = analyse(t, s, M, R, L)
    cur = a.signals["curvature"]
    assert cur["eta2"][1] > 0.95 and cur["corr"][1] > 0.95
    assert np.all(cur["eta2"][[0, 2, 3, 4, 5, 6]] < 0.05)
    for name, sig in a.signals.items():
        if name != "curvature" and not sig["constant"]:
            assert sig["eta2"][1] < 0.3 and abs(sig["corr"][1]) < 0.3, name
    assert a.signals["v"]["constant"]
    c = a.concentration
    assert c["signal"]["name"] == "curvature"
    assert c["by_kind"]["horizontal curve"]["share"] > 0.95
    assert "curvature explains" in c["sentence"] and "horizontal curves hold" in c["sentence"]


def test_model_signal_given_by_the_caller(track7):
    t, s, M, noise = record(10.0, seed=8)
    rng = np.random.default_rng(2)
    v_joint = np.convolve(rng.normal(0, 1, len(t)), np.ones(60) / 60, mode="same")
    R = noise.copy()
    R[:, 0] += 400.0 * v_joint
    a = analyse(t, s, M, R, track7.length, model_signals={"v_joint": v_joint})
    assert np.array_equal(a.track["v_joint"], v_joint)
    assert a.signals["v_joint"]["eta2"][0] > 0.8 and a.signals["v_joint"]["corr"][0] > 0.9
    assert a.concentration["signal"]["name"] == "v_joint"


def test_wrapped_s_gives_the_same_analysis(track7):
    L = track7.length
    t, s, M, noise = record(40.0, seed=9)
    a = analyse(t, s, M, noise, L)
    b = analyse(t, np.mod(s, L), M, noise, L)
    assert np.allclose(a.s, b.s)
    assert np.allclose(a.fold["mean"], b.fold["mean"], equal_nan=True)
    assert np.allclose(a.orders["amplitude"], b.orders["amplitude"])
    assert any("unwrapped" in n for n in b.notes)


def test_without_a_layout(track7):
    t, s, M, noise = record(1.0, seed=4)
    a = analyse_residual(M, M - noise, t, s, 65.0)
    assert "curvature" not in a.track and "motor" not in a.track and "v" in a.track
    assert a.orders["named"]["wheel"] == pytest.approx(1 / (2 * math.pi * 0.05))
    assert "motor" not in a.orders["named"]
    assert any("r_drive not given" in n for n in a.notes)


# ----------------------------------------------------------------------------- reports
def test_describe_and_json(track7):
    t, s, M, noise = record(3.0, seed=11)
    R = noise.copy()
    R[:, 3] += 20 * np.sin(2 * np.pi * s / (2 * math.pi * 0.045))
    a = analyse(t, s, M, R, track7.length)
    md = describe(a)
    assert md.startswith("### Residual analysis")
    assert all(f"| {ch} |" in md for ch in FORCE_CHANNELS)
    assert "resolution" in md
    js = to_json(a)
    text = json.dumps(js, allow_nan=False)
    back = json.loads(text)
    assert back["channels"] == list(FORCE_CHANNELS)
    assert len(back["fold"]["mean"]) == len(a.fold["count"]) and len(back["fold"]["mean"][0]) == 7
    assert back["orders"]["lines"]["wheel"]["line_snr"][3] > 20
    assert back["concentration"]["line"]["name"] == "wheel"
    assert "amplitude" not in back["orders"] and "residual" not in back


# ----------------------------------------------------------------------------- bad input
def _good():
    t, s, M, noise = record(0.5, seed=1)
    return dict(measured=M, simulated=M - noise, times=t, s=s, track_length=65.0)


@pytest.mark.parametrize("change, message", [
    (lambda g: g.update(simulated=g["simulated"][:, :6]), r"simulated has shape \(150, 6\)"),
    (lambda g: g.update(simulated=g["simulated"][:-1]), r"simulated has 149 samples but measured has 150"),
    (lambda g: g.update(times=g["times"][:-1]), r"times has shape \(149,\).*shape mismatch"),
    (lambda g: g.update(s=g["s"][:-2]), r"s has shape \(148,\)"),
    (lambda g: g["measured"].__setitem__((7, 2), np.nan),
     r"measured has 1 non-finite value\(s\) \(NaN or Inf\), the first at sample 7, channel transducer.joint.F_z"),
    (lambda g: g["simulated"].__setitem__((3, 0), np.inf), r"simulated has 1 non-finite value"),
    (lambda g: g["times"].__setitem__(5, np.nan), r"times has 1 non-finite value"),
    (lambda g: g["times"].__setitem__(10, g["times"][9]), r"times is not strictly increasing: sample 10"),
    (lambda g: g["times"].__setitem__(10, g["times"][8] - 1e-3), r"times is not strictly increasing"),
    (lambda g: g["s"].__setitem__(slice(50, None), g["s"][50:] - 0.5), r"s goes backwards by 0\.493\d* m at sample 50"),
    (lambda g: g.update(track_length=0.0), r"track_length = 0.0: must be positive"),
    (lambda g: g.update(model_signals={"v_joint": np.zeros(10)}), r"model_signals\['v_joint'\] has shape \(10,\)"),
    (lambda g: g.update(nbins=0), r"nbins = 0"),
    (lambda g: g.update(measured=g["measured"][:10], simulated=g["simulated"][:10], times=g["times"][:10],
                        s=g["s"][:10]), r"measured has 10 samples: at least 16"),
])
def test_bad_input_is_named(change, message):
    g = _good()
    change(g)
    with pytest.raises(ValueError, match=message):
        analyse_residual(g.pop("measured"), g.pop("simulated"), g.pop("times"), g.pop("s"), g.pop("track_length"),
                         **g)


# ----------------------------------------------------------------------------- figures
def test_figures_are_written(track7, tmp_path):
    from lss_app.figures.residual import residual_figures
    t, s, M, noise = record(6.0, seed=12)       # 20-32 m: a vertical curve, a motor, into a curve
    R = noise.copy()
    R[:, 1] += 300 * track7.curvature(s)[0]
    R[:, 3] += 20 * np.sin(2 * np.pi * s / (2 * math.pi * 0.045))
    a = analyse(t, s, M, R, track7.length)
    paths = residual_figures(a, tmp_path / "fig", measured=M, simulated=M - R)
    names = sorted(p.name for p in paths)
    expected = sorted(f"residual_{k}.{e}" for k in ("time", "fold", "orders", "signals", "forces")
                      for e in ("png", "svg"))
    assert names == expected
    for p in paths:
        assert p.is_file() and p.stat().st_size > 5000, p
        head = p.read_bytes()[:400]
        assert head.startswith(b"\x89PNG") if p.suffix == ".png" else b"<svg" in head
