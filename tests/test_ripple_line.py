"""The ripple's pitch from the residual's line (identification.loop.ripple_line) and
the hypotheses the catalogue builds around it."""
import math

import numpy as np
import pytest

from identification.loop.catalogue import Context, MotorRipple
from identification.loop.ripple_line import LINE_RATIO, ripple_lines

BAND = (MotorRipple.P_MIN, MotorRipple.P_MAX)


def _record(pitch=None, amp=20.0, seed=0, n=300, v=2.0, rate=300.0, channel=0):
    """A residual of 7 channels: white noise (2 N), a sinusoid of `pitch` in the
    track position on one channel, the cart's speed slightly uneven."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    s = 10.0 + v * t + 0.01 * np.sin(2 * math.pi * 1.3 * t)
    r = rng.normal(0.0, 2.0, (n, 7))
    if pitch is not None:
        r[:, channel] += amp * np.cos(2 * math.pi * s / pitch + rng.uniform(0, 2 * math.pi))
    return r, s


@pytest.mark.parametrize("pitch", [0.055, 0.073, 0.12, 0.19])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_line_gives_the_pitch_within_a_tenth_of_its_resolution(pitch, seed):
    r, s = _record(pitch, seed=seed, channel=seed % 7)
    lines = ripple_lines(r, s, BAND)
    assert lines, "no line found"
    ln = lines[0]
    assert ln.ratio >= LINE_RATIO
    assert abs(ln.order - 1 / pitch) <= 0.1 * ln.resolution
    assert ln.relative_cell == pytest.approx(ln.resolution / ln.order)


def test_white_noise_claims_a_line_rarely():
    hits = sum(bool(ripple_lines(*_record(None, seed=k), BAND)) for k in range(40))
    assert hits <= 2


def test_two_lines_strongest_first_and_a_cell_apart():
    r, s = _record(0.08, amp=30.0, seed=4, channel=0)
    r2, _ = _record(0.15, amp=15.0, seed=5, channel=3)
    r[:, 3] = r2[:, 3]
    lines = ripple_lines(r, s, BAND)
    assert len(lines) == 2
    assert abs(lines[0].pitch - 0.08) < 0.002 and abs(lines[1].pitch - 0.15) < 0.006
    assert lines[0].ratio >= lines[1].ratio


def test_no_line_when_the_cart_stands_or_the_record_is_short():
    r, s = _record(0.08)
    assert ripple_lines(r, np.full_like(s, 3.0), BAND) == []
    assert ripple_lines(r[:10], s[:10], BAND) == []
    s_bad = s.copy()
    s_bad[5] = np.nan
    assert ripple_lines(r, s_bad, BAND) == []


def _ctx(lines):
    return Context("layout7", 100.0, np.zeros(1), (0.0, 2.0), 52, 2.0, ripple_lines=lines)


def test_hypotheses_around_a_line_and_their_extension():
    r, s = _record(0.1, seed=7)
    lines = ripple_lines(r, s, BAND)
    eff = MotorRipple()
    hyps = eff.hypotheses(_ctx(lines))
    assert len(hyps) == len(lines) * len(eff.LINE_STEPS)
    assert all(h.origin == "line" and h.spread > 0 for h in hyps)
    assert all(p.params["effects.motor_ripple.amplitude"] == eff.LINE_PROBE for h in hyps for p in h.probes)
    pitches = sorted(h.fixed["effects.motor_ripple.pitch"] for h in hyps[:len(eff.LINE_STEPS)])
    assert pitches[0] < lines[0].pitch < pitches[-1]
    h = hyps[0]
    ext = eff.extension(h, np.array([3.0, 4.0]))
    lo, hi = ext.free["effects.motor_ripple.pitch"]
    p = h.fixed["effects.motor_ripple.pitch"]
    assert lo < p < hi and hi / lo - 1 == pytest.approx(2 * h.spread, rel=0.05)
    plo, phi = ext.free["effects.motor_ripple.phase"]
    assert phi - plo == pytest.approx(2 * math.pi)
    assert ext.x0["effects.motor_ripple.amplitude"] == pytest.approx(5.0)
    # Bonferroni: the line search counts as the whole scan
    assert eff.hypothesis_count(len(hyps)) == len(eff.pitches())


def test_without_a_line_the_scan():
    eff = MotorRipple()
    hyps = eff.hypotheses(_ctx([]))
    assert len(hyps) == len(eff.pitches()) and all(h.origin == "scan" for h in hyps)
    ext = eff.extension(hyps[0], np.array([30.0, 0.0]))
    lo, hi = ext.free["effects.motor_ripple.phase"]
    assert hi - lo == pytest.approx(math.pi)


def test_a_ripple_in_the_chain_shows_its_line():
    """Through the FMU: a 100 N ripple of 73 mm under the transducer cart 26
    (as on one record of the rates benchmark, where the 100 N scan ranked
    117 mm first); at the clean model's true CoRs one of the residual's
    lines is the ripple's order within half a resolution cell."""
    from identification.loop.locate import signals_at, unwrap
    from identification.objective.problem import tared
    from identification.loop.synthetic import TRUTH, cart_trigger, make_problem
    from lss_fmu.layouts import load_track
    from lss_fmu.runner import LazySimulator
    sim = LazySimulator()
    pitch = 0.07304
    params = {"effects.motor_ripple.amplitude": 100.0, "effects.motor_ripple.pitch": pitch,
              "effects.motor_ripple.phase": 4.75}
    p, _ = make_problem(params, 417217355, transducer=26, s_m=cart_trigger(26, sim()), sim=sim)
    x = np.array([TRUTH[k] for k in p.free])
    r = tared(p.samples - p.simulate(x), p.tare)
    s = unwrap(signals_at(p, x)["transducer.s"], float(load_track(p.layout).length))
    lines = ripple_lines(r, s, BAND)
    assert any(abs(ln.order - 1 / pitch) <= 0.5 * ln.resolution for ln in lines), \
        [(round(ln.pitch, 4), round(ln.ratio, 1)) for ln in lines]
    # and without the ripple no line of that order
    p0, _ = make_problem({}, 417217355, transducer=26, s_m=cart_trigger(26, sim()), sim=sim)
    r0 = tared(p0.samples - p0.simulate(x), p0.tare)
    assert not any(abs(ln.order - 1 / pitch) <= ln.resolution for ln in ripple_lines(r0, s, BAND))
