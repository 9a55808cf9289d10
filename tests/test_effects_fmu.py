"""The effects catalogue in the FMU (issue 7, docs/effects.md).

Each effect is off by default and then changes nothing, bit for bit; each,
switched on, changes the transducer signals as its physics says, with the
expected value computed from the model's own parameters (statics of the
cart lever, the preload law, the wheel-revolution and pole-pitch
frequencies, the resistance law); the energy balance holds with them; bad
values are refused naming the variable. Runs use the 'oval' layout (32 carts,
10.6 m straights, level), cart 0 starting at the beginning of a straight."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lss_fmu.layouts import load_track
from lss_fmu.runner import SimulationError
from lss_fmu.variables import BY_NAME, FORCE_CHANNELS, VARIABLES


@pytest.fixture
def sim(path_sim):
    """Every test here runs on each right-hand-side path: scalar, AVX2,
    AVX-512 (tests/conftest.py path_sim; skipped where the CPU lacks one)."""
    return path_sim

G = 9.81
X_AXLE = 0.40   # driving-wheel axle ahead of the CG, body x (docs/model.md, cart geometry)
COAST = {"drive.Kp": 0.0, "drive.Ki": 0.0, "wheel.mu_roll": 0.0}
ELASTIC = {f"contact.e_{k}": 1.0 for k in ("JA", "JR", "SW", "RW")}
ENERGY = ["energy.E_mech", "energy.W_damping", "energy.W_motor", "energy.W_rolling"]
EFFECTS = [v for v in VARIABLES if v.name.startswith("effects.")]
ALL_REAL_OUTPUTS = [v.name for v in VARIABLES if v.causality == "output" and v.type == "Real"]
DRIVING = ["transducer.driving.F_left", "transducer.driving.F_right"]
DT = 0.002


def driving_sum(df) -> np.ndarray:
    return (df["transducer.driving.F_left"] + df["transducer.driving.F_right"]).to_numpy()


def spectrum(x: np.ndarray, dt: float = DT, pad: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Single-sided amplitude spectrum (Hann window, mean removed), zero-padded
    pad times so that a peak is located finer than the 1/T bins."""
    x = x - x.mean()
    X = np.abs(np.fft.rfft(x * np.hanning(len(x)), n=pad * len(x))) * 4.0 / len(x)
    return np.fft.rfftfreq(pad * len(x), dt), X


def dominant(x: np.ndarray, lo: float = 1.0, hi: float = 100.0) -> float:
    f, X = spectrum(x)
    band = (f > lo) & (f < hi)
    return float(f[band][np.argmax(X[band])])


def amplitude_at(x: np.ndarray, freq: float, half_width: float = 0.4) -> float:
    f, X = spectrum(x)
    return float(X[np.abs(f - freq) <= half_width].max())


def on_straight(df, lo: float = 1.0, hi: float = 9.5, t0: float = 0.5) -> np.ndarray:
    s = df["transducer.s"].to_numpy()
    return (s > lo) & (s < hi) & (df["time"].to_numpy() > t0)


# --- off by default -------------------------------------------------------------------------------

def test_defaults_change_nothing_bit_for_bit(sim):
    """Every effect parameter set explicitly to its default gives the very run
    of an FMU where none was set: all Real outputs equal bit for bit."""
    plain = sim.simulate(1.0, 0.01, {"layout.name": "layout7"}, ALL_REAL_OUTPUTS)
    defaults = {v.name: v.start for v in EFFECTS}
    assert len(defaults) == 31
    again = sim.simulate(1.0, 0.01, {"layout.name": "layout7", **defaults}, ALL_REAL_OUTPUTS)
    np.testing.assert_array_equal(plain.to_numpy(), again.to_numpy())
    assert sim.get("cart.r_drive") == 0.045  # layout7: wheel type C


@pytest.mark.parametrize("name, off", [
    ("effects.wheel_oor.order", 3), ("effects.wheel_oor.phase_left", 1.0), ("effects.wheel_oor.cart", 4),
    ("effects.track_bump.s", 3.0), ("effects.track_bump.length", 1.0), ("effects.motor_ripple.pitch", 0.3),
    ("effects.motor_ripple.phase", 2.0), ("effects.mass.seed", 11)])
def test_shape_parameters_alone_change_nothing(sim, name, off):
    """Shape parameters of an effect whose amplitude is zero leave the run as it was."""
    plain = sim.simulate(0.5, 0.01, {"layout.name": "oval"}, FORCE_CHANNELS)
    other = sim.simulate(0.5, 0.01, {"layout.name": "oval", name: off}, FORCE_CHANNELS)
    np.testing.assert_array_equal(plain.to_numpy(), other.to_numpy())


# --- sensor ---------------------------------------------------------------------------------------

def test_sensor_gain_and_offset_are_exactly_the_sensor(sim):
    """output = (1 + g) F + o on every force channel, with the physics untouched."""
    outs = FORCE_CHANNELS + ["transducer.s", "transducer.v", "energy.E_mech"]
    plain = sim.simulate(1.0, 0.01, {"layout.name": "oval"}, outs)
    rng = np.random.default_rng(3)
    gains = dict(zip(FORCE_CHANNELS, rng.uniform(-0.3, 0.3, 7)))
    offsets = dict(zip(FORCE_CHANNELS, rng.uniform(-500.0, 500.0, 7)))
    params = {"layout.name": "oval"}
    for ch in FORCE_CHANNELS:
        short = ch[len("transducer."):]
        params[f"effects.sensor.gain.{short}"] = gains[ch]
        params[f"effects.sensor.offset.{short}"] = offsets[ch]
    sensed = sim.simulate(1.0, 0.01, params, outs)
    for ch in FORCE_CHANNELS:
        # the C side may fuse the multiply-add: equal to rounding, not to the bit
        np.testing.assert_allclose(sensed[ch].to_numpy(), (1.0 + gains[ch]) * plain[ch].to_numpy() + offsets[ch],
                                   rtol=1e-13, atol=1e-9)
    np.testing.assert_array_equal(sensed[outs[7:]].to_numpy(), plain[outs[7:]].to_numpy())


# --- masses ---------------------------------------------------------------------------------------

def lever_statics(mass: np.ndarray, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """Level chain at rest: cart j rests on its axle (x = X_AXLE) and, at its
    rear joint (x = -p/2), on cart j-1's front joint, and carries cart j+1's
    rear at its front joint (x = +p/2). Moments about the axle:
    R_j (X_AXLE + p/2) + R_{j+1} (p/2 - X_AXLE) = X_AXLE m_j g, cyclic.
    Returns the rear-joint loads R and the axle loads A_j = m_j g + R_{j+1} - R_j."""
    n = len(mass)
    M = np.zeros((n, n))
    for j in range(n):
        M[j, j] = X_AXLE + pitch / 2
        M[j, (j + 1) % n] = pitch / 2 - X_AXLE
    R = np.linalg.solve(M, X_AXLE * mass * G)
    return R, mass * G + np.roll(R, -1) - R


def test_transducer_mass_factor_loads_its_wheels(sim):
    """The transducer cart twice as heavy: its driving wheels carry what the
    cart lever says, m g (f p/2 + x_a)/(x_a + p/2) (the cart rests partly on
    the joint of the cart behind, so the wheel load grows less than f)."""
    outs = FORCE_CHANNELS + ["transducer.s"]
    loads = {}
    for f in (1.0, 2.0):
        p = {"layout.name": "oval", **COAST, "track.guide_gap": -0.0005, "effects.mass.transducer_factor": f}
        df = sim.simulate(4.0, 0.01, p, outs)
        on = on_straight(df)
        assert on.sum() > 200
        loads[f] = driving_sum(df)[on].mean()
    m, n, pitch = sim.get("cart.mass"), sim.get("chain.n_carts"), sim.get("chain.pitch")
    mass = np.full(n, m)
    mass[0] *= 2.0
    expected = lever_statics(mass, pitch)[1][0]
    assert expected == pytest.approx(m * G * (2.0 * pitch / 2 + X_AXLE) / (X_AXLE + pitch / 2))
    assert loads[1.0] == pytest.approx(m * G, rel=0.005)
    assert loads[2.0] == pytest.approx(expected, rel=0.01)
    assert loads[2.0] > 1.5 * loads[1.0]


def splitmix64(x: int) -> tuple[int, int]:
    mask = (1 << 64) - 1
    x = (x + 0x9E3779B97F4A7C15) & mask
    z = x
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
    return x, z ^ (z >> 31)


def mass_normal(seed: int, i: int) -> float:
    """The FMU's z_i (fmu_src/effects.c, docs/effects.md), reimplemented."""
    x, a = splitmix64((seed << 32) | i)
    x, b = splitmix64(x)
    u1 = ((a >> 11) + 0.5) * 2.0 ** -53
    u2 = (b >> 11) * 2.0 ** -53
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


def test_mass_spread_is_seeded_and_loads_the_joints(sim):
    """Spread masses from the documented PRNG: the transducer's front joint
    carries the rear of cart 1 and its wheels the rest, as the cyclic lever
    statics of those masses say; the same seed repeats, another differs."""
    n = 32
    spread, seed = 0.2, 7
    z = np.clip([mass_normal(seed, i) for i in range(n)], -3, 3)
    assert np.std(z) > 0.5
    outs = FORCE_CHANNELS + ["transducer.s"]
    p = {"layout.name": "oval", **COAST, "track.guide_gap": -0.0005, "effects.mass.spread": spread,
         "effects.mass.seed": seed}
    df = sim.simulate(4.0, 0.01, p, outs)
    assert sim.get("chain.n_carts") == n
    on = on_straight(df)
    mass = sim.get("cart.mass") * (1.0 + spread * z)
    mass[0] = sim.get("cart.mass")  # the transducer is not spread
    R, A = lever_statics(mass, sim.get("chain.pitch"))
    assert -df.loc[on, "transducer.joint.F_z"].mean() == pytest.approx(R[1], rel=0.01)
    assert driving_sum(df)[on].mean() == pytest.approx(A[0], rel=0.01)
    assert abs(R[1] / (X_AXLE * sim.get("cart.mass") * G / sim.get("chain.pitch")) - 1) > 0.03  # it moved
    again = sim.simulate(4.0, 0.01, p, outs)
    np.testing.assert_array_equal(df.to_numpy(), again.to_numpy())
    other = sim.simulate(4.0, 0.01, {**p, "effects.mass.seed": seed + 1}, outs)
    assert not np.array_equal(df.to_numpy(), other.to_numpy())


# --- resistance -----------------------------------------------------------------------------------

def test_running_resistance_raises_thrust_by_its_law(sim):
    """In steady running at v the motors push N (c1 v + c2 v^2) more."""
    thrust, speed = {}, {}
    for c1, c2 in ((0.0, 0.0), (20.0, 0.0), (0.0, 5.0)):
        df = sim.simulate(8.0, 0.01, {"layout.name": "oval", "effects.resistance.c1": c1,
                                      "effects.resistance.c2": c2}, ["drive.F_total", "chain.v_mean", "transducer.v"])
        late = df["time"] > 3.0
        thrust[c1, c2] = df.loc[late, "drive.F_total"].mean()
        speed[c1, c2] = df.loc[late, "chain.v_mean"].mean()
        assert df.loc[late, "transducer.v"].mean() == pytest.approx(speed[c1, c2], rel=0.01)
    n = sim.get("chain.n_carts")
    v = speed[20.0, 0.0]
    assert v == pytest.approx(2.0, rel=0.01)
    assert thrust[20.0, 0.0] - thrust[0.0, 0.0] == pytest.approx(n * 20.0 * v, rel=0.02)
    v = speed[0.0, 5.0]
    assert thrust[0.0, 5.0] - thrust[0.0, 0.0] == pytest.approx(n * 5.0 * v * v, rel=0.02)


# --- track bump -----------------------------------------------------------------------------------

def test_track_bump_hits_the_transducer_where_it_is(sim):
    """A 2 mm cosine bump 0.2 m long at s_b = 4.25 m, the transducer (cart 3,
    axle at 3.75 m) the first cart to reach it: its driving-wheel force is the
    same bit for bit until its wheels reach the bump, jumps by well over 100 N
    there (up on the rising flank, down over the crest), and is little changed
    once past."""
    s_b, l, H = 4.25, 0.2, 0.002
    outs = DRIVING + ["transducer.s", "transducer.v"]
    base = {"layout.name": "oval", "chain.transducer": 3}
    plain = sim.simulate(0.6, DT, base, outs)
    bumped = sim.simulate(0.6, DT, {**base, "effects.track_bump.height": H, "effects.track_bump.s": s_b,
                                    "effects.track_bump.length": l}, outs)
    dF = driving_sum(bumped) - driving_sum(plain)
    x = plain["transducer.s"].to_numpy() - s_b
    before, on, after = x < -l / 2 - 0.02, np.abs(x) < l / 2, x > l / 2 + 0.2
    assert before.sum() > 50 and on.sum() > 40 and after.sum() > 30
    assert np.all(dF[before] == 0.0)
    rising, crest = (x > -l / 2) & (x < -l / 4), np.abs(x) < l / 8
    assert dF[rising].max() > 100.0
    assert dF[crest].min() < -100.0
    assert np.abs(dF[after]).max() < 0.25 * np.abs(dF[on]).max()
    # the rigid cart follows the bump: m_eff h'' v^2 sets the scale of the jump
    v = plain["transducer.v"].mean()
    curvature = 0.5 * H * (2 * np.pi / l) ** 2 * v ** 2   # peak vertical acceleration, m/s^2
    assert 0.5 * curvature * sim.get("cart.mass") / 4 < np.abs(dF[on]).max() < 4 * curvature * sim.get("cart.mass")


# --- out-of-round wheel ---------------------------------------------------------------------------

def test_out_of_round_wheel_forces_at_the_revolution_frequency(sim):
    """An eccentric (k = 1) transducer wheel pair makes the driving-wheel force
    oscillate at v / (2 pi r0), a two-lobed one (k = 2) at twice that; in
    anti-phase (phi_right = pi) the pair rocks the cart and the sum hardly
    moves while the difference does; on another cart the transducer's wheels
    hardly see it."""
    outs = DRIVING + ["transducer.s", "transducer.v"]
    base = {"layout.name": "oval"}
    found = {}
    for k, a in ((1, 0.0005), (2, 0.0002)):
        df = sim.simulate(4.5, DT, {**base, "effects.wheel_oor.amplitude": a, "effects.wheel_oor.order": k}, outs)
        r0 = sim.get("cart.r_drive")
        w = df["time"].to_numpy() > 0.6
        f_rev = df.loc[w, "transducer.v"].mean() / (2 * np.pi * r0)
        found[k] = (dominant(driving_sum(df)[w]), k * f_rev, amplitude_at(driving_sum(df)[w], k * f_rev))
    plain = sim.simulate(4.5, DT, base, outs)
    w = plain["time"].to_numpy() > 0.6
    for k, (peak, expected, amp) in found.items():
        assert peak == pytest.approx(expected, abs=0.2), found
        assert amp > 5 * amplitude_at(driving_sum(plain)[w], expected), found
    f1 = found[1][1]
    rock = sim.simulate(4.5, DT, {**base, "effects.wheel_oor.amplitude": 0.0005,
                                  "effects.wheel_oor.phase_right": np.pi}, outs)
    diff = (rock["transducer.driving.F_left"] - rock["transducer.driving.F_right"]).to_numpy()[w]
    assert amplitude_at(driving_sum(rock)[w], f1) < 0.3 * amplitude_at(diff, f1)
    assert dominant(diff) == pytest.approx(f1, abs=0.3)
    elsewhere = sim.simulate(4.5, DT, {**base, "effects.wheel_oor.amplitude": 0.0005,
                                       "effects.wheel_oor.cart": 16}, outs)
    assert amplitude_at(driving_sum(elsewhere)[w], f1) < 0.2 * found[1][2]


def test_fmu_state_carries_the_wheel_angle(sim):
    """The rolled distance is part of the FMU state: a run restored from a
    serialised state repeats the original's forces bit for bit."""
    sim.start({"layout.name": "oval", "effects.wheel_oor.amplitude": 0.001, "effects.wheel_oor.order": 3,
               "effects.wheel_oor.phase_left": 0.4})
    vrs = [sim.vr(c) for c in DRIVING]
    for _ in range(50):
        sim.step(0.01)
    state = sim.fmu.getFMUstate()
    blob = sim.fmu.serializeFMUstate(state)
    sim.fmu.freeFMUstate(state)
    t_saved = sim.time
    first = []
    for _ in range(30):
        sim.step(0.01)
        first.append(sim.fmu.getReal(vrs))
    restored = sim.fmu.deSerializeFMUstate(blob)
    sim.fmu.setFMUstate(restored)
    sim.fmu.freeFMUstate(restored)
    sim.time = t_saved
    second = []
    for _ in range(30):
        sim.step(0.01)
        second.append(sim.fmu.getReal(vrs))
    assert np.array_equal(first, second)
    assert np.ptp(np.sum(first, axis=1)) > 20.0  # the wheels did act


# --- motor ripple ---------------------------------------------------------------------------------

def test_motor_ripple_at_the_pole_pitch_frequency(sim):
    """Cogging of A = 200 N with pole pitch p = 0.2 m. Each plate feels it at
    v / p while it crosses a motor; the plates follow each other every
    p_c / v (p_c the plate length, = the assembled pitch), so the chain's
    total ripple repeats with that period: its spectrum is lines at multiples
    of v / p_c under the single-plate peak at v / p. The total thrust peaks on
    such a line within v / (2 p_c) of v / p, the transducer's joint force gets
    content there, and the ripple acts with the controller off too."""
    p_pole, A = 0.2, 200.0
    outs = ["transducer.joint.F_x", "drive.F_total", "chain.v_mean"]
    plain = sim.simulate(4.0, DT, {"layout.name": "oval"}, outs)
    rip = sim.simulate(4.0, DT, {"layout.name": "oval", "effects.motor_ripple.amplitude": A,
                                 "effects.motor_ripple.pitch": p_pole}, outs)
    p_c = sim.get("chain.pitch") + 0.01 / sim.get("chain.n_carts")  # plate = pitch + stretch
    w = plain["time"].to_numpy() > 0.6
    v = rip.loc[w, "chain.v_mean"].mean()
    f_pole, f_plate = v / p_pole, v / p_c
    peak = dominant(rip["drive.F_total"].to_numpy()[w], 2.0)
    assert abs(peak - f_pole) <= 0.5 * f_plate + 0.1, (peak, f_pole, f_plate)
    assert abs(peak - round(peak / f_plate) * f_plate) < 0.15, (peak, f_plate)
    assert amplitude_at(rip["drive.F_total"].to_numpy()[w], peak) > 0.5 * A
    jx, jx0 = rip["transducer.joint.F_x"].to_numpy()[w], plain["transducer.joint.F_x"].to_numpy()[w]
    assert amplitude_at(jx, peak) > 4 * amplitude_at(jx0, peak)
    coast = sim.simulate(1.0, DT, {"layout.name": "oval", **COAST, "effects.motor_ripple.amplitude": A,
                                   "effects.motor_ripple.pitch": p_pole}, ["drive.F_total", "drive.F_cmd"])
    assert np.all(coast["drive.F_cmd"] == 0.0)
    assert coast["drive.F_total"].abs().max() > 0.2 * A


# --- joint clearance ------------------------------------------------------------------------------

def test_joint_clearance_lowers_the_axial_preload(sim, data_dir):
    """Play g in every joint: on a level straight the joint tension is that
    of the stretch less the play, preload ((d/N - g) / (d/N))^1.5."""
    layout = str(data_dir / "big_oval.layout")
    track = load_track(layout)
    d, gap = 0.03, 5e-5
    tension = {}
    for g in (0.0, gap):
        params = {"layout.name": layout, **COAST, "track.guide_gap": -0.0005, "chain.pretension": d,
                  "effects.joint_clearance.gap": g}
        df = sim.simulate(3.0, 0.01, params, ["transducer.joint.F_x", "transducer.s"])
        on = on_straight(df, 1.0, track.s0[1] - 1.0, 1.0)
        assert on.sum() > 100
        tension[g] = df.loc[on, "transducer.joint.F_x"].mean()
    stretch = d / sim.get("chain.n_carts")
    preload = sim.get("chain.preload")
    assert tension[0.0] == pytest.approx(preload, rel=0.02)
    assert tension[gap] == pytest.approx(preload * ((stretch - gap) / stretch) ** 1.5, rel=0.02)


def test_joint_axial_velocity_is_the_closing_rate(sim):
    """transducer.joint.v_axial is -d/dt of the joint's axial stretch D_a,
    which (elastic joint, F_x = sign(D_a) K |D_a|^1.5, tension positive) is
    sign(F_x) (|F_x| / K)^(2/3)."""
    params = {"layout.name": "oval", **ELASTIC}
    dt = 0.0002  # the joint rings at ~130 Hz: fine steps for the finite difference
    df = sim.simulate(0.6, dt, params, ["transducer.joint.F_x", "transducer.joint.v_axial"])
    K = sim.get("chain.preload") / (0.01 / sim.get("chain.n_carts")) ** 1.5
    F = df["transducer.joint.F_x"].to_numpy()
    stretch = np.sign(F) * (np.abs(F) / K) ** (2.0 / 3.0)
    rate = np.gradient(stretch, dt)
    v = df["transducer.joint.v_axial"].to_numpy()
    assert F.max() > 1000.0 and F.min() < -1000.0  # both ways: the sign convention is tested
    slope = np.polyfit(v, rate, 1)[0]
    assert slope == pytest.approx(-1.0, rel=0.05)
    assert np.corrcoef(v, rate)[0, 1] < -0.99


# --- energy ---------------------------------------------------------------------------------------

def test_energy_balance_with_ripple_and_resistance(sim):
    """Driven, with ripple, running resistance and unequal masses: E(t) - E(0)
    = W_motor - W_damping - W_rolling (ripple work is motor work, resistance
    is rolling loss, E counts every cart's own mass)."""
    p = {"layout.name": "demo", "effects.motor_ripple.amplitude": 200.0, "effects.resistance.c1": 10.0,
         "effects.resistance.c2": 2.0, "effects.mass.spread": 0.1, "effects.mass.transducer_factor": 1.5}
    df = sim.simulate(5.0, 0.05, p, ENERGY, tolerance=1e-5)
    lhs = df["energy.E_mech"] - df["energy.E_mech"].iloc[0]
    rhs = df["energy.W_motor"] - df["energy.W_damping"] - df["energy.W_rolling"]
    scale = df["energy.W_motor"].abs().max()
    assert scale > 5000.0 and df["energy.W_rolling"].iloc[-1] > 3000.0  # the effects really worked
    assert np.max(np.abs(lhs - rhs)) < 1e-3 * scale


def test_geometric_effects_conserve_energy(sim):
    """Undamped and undriven, with a track bump, out-of-round wheels, joint
    play and unequal masses: the contacts stay conservative, E drifts < 0.1 %
    in 5 s (as without effects; the bump alone does work of order m g H per
    passage, so a missing slope force would show)."""
    p = {"layout.name": "demo", **COAST, **ELASTIC, "effects.track_bump.height": 0.002,
         "effects.track_bump.s": 5.0, "effects.wheel_oor.amplitude": 0.001, "effects.wheel_oor.order": 3,
         "effects.joint_clearance.gap": 1e-4, "effects.mass.spread": 0.1}
    df = sim.simulate(5.0, 0.1, p, ENERGY)
    E = df["energy.E_mech"].to_numpy()
    assert np.max(np.abs(E - E[0])) < 1e-3 * abs(E[0])
    assert df["energy.W_damping"].abs().max() < 1e-9


# --- bad values -----------------------------------------------------------------------------------

BAD = [
    ("effects.wheel_oor.amplitude", float("nan")), ("effects.wheel_oor.amplitude", 0.006),
    ("effects.wheel_oor.order", 0), ("effects.wheel_oor.order", 9), ("effects.wheel_oor.cart", -2),
    ("effects.wheel_oor.phase_left", float("inf")), ("effects.track_bump.height", -0.0051),
    ("effects.track_bump.s", -1.0), ("effects.track_bump.length", 0.0), ("effects.track_bump.length", 5.5),
    ("effects.joint_clearance.gap", 0.0051), ("effects.motor_ripple.amplitude", 1001.0),
    ("effects.motor_ripple.pitch", 0.0), ("effects.motor_ripple.phase", float("nan")),
    ("effects.resistance.c1", -1.0), ("effects.resistance.c2", float("nan")),
    ("effects.sensor.gain.joint.F_x", 0.51), ("effects.sensor.gain.driving.F_right", -0.51),
    ("effects.sensor.offset.steering.F_left", 1e4 + 1), ("effects.mass.transducer_factor", 0.19),
    ("effects.mass.transducer_factor", 5.01), ("effects.mass.spread", 0.31), ("effects.mass.seed", -1),
]


@pytest.mark.parametrize("name, value", BAD)
def test_bad_values_are_refused(sim, name, value):
    with pytest.raises(SimulationError, match=name.replace(".", r"\.")):
        sim.start({"layout.name": "oval", name: value})
    errors = [m for s, _, m in sim.messages if s == 3]  # fmi2Error
    assert errors and name in errors[-1]
    assert sim.get(name) == BY_NAME[name].start  # the value was not taken


@pytest.mark.parametrize("name, value, why", [
    ("effects.wheel_oor.cart", 32, "32 carts"), ("effects.track_bump.s", 41.0, "track length")])
def test_values_beyond_the_chain_are_refused_at_initialisation(sim, name, value, why):
    with pytest.raises(SimulationError, match="initialisation failed"):
        sim.start({"layout.name": "oval", name: value})
    errors = [m for s, _, m in sim.messages if s == 3]
    assert errors and name in errors[-1] and why in errors[-1]
