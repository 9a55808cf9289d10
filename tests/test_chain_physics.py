"""The chain against statics, energy balances, gravity, centripetal forces and
its speed controller (issue 2). Every expected value is computed from the
model's own parameters (cart mass, preload, layout geometry), not pasted."""
from __future__ import annotations

import numpy as np
import pytest

from lss_fmu.layouts import load_track


@pytest.fixture
def sim(path_sim):
    """Every test here runs on each right-hand-side path: scalar, AVX2,
    AVX-512 (tests/conftest.py path_sim; skipped where the CPU lacks one)."""
    return path_sim

G = 9.81
COAST = {"drive.Kp": 0.0, "drive.Ki": 0.0, "wheel.mu_roll": 0.0}
ELASTIC = {f"contact.e_{k}": 1.0 for k in ("JA", "JR", "SW", "RW")}
ENERGY = ["energy.E_mech", "energy.W_damping", "energy.W_motor", "energy.W_rolling", "chain.v_mean"]


def test_statics_level_straight(sim, data_dir):
    """Coasting at constant speed (no drive, no resistance) on a level oval
    with gentle curves: on the straights each driving wheel carries half a
    cart weight and the front joint carries the pretension preload."""
    layout = str(data_dir / "big_oval.layout")
    track = load_track(layout)
    params = {"layout.name": layout, **COAST, "track.guide_gap": -0.0005, "chain.pretension": 0.03}
    df = sim.simulate(6.0, 0.01, params, ["transducer.joint.F_x", "transducer.driving.F_left",
                                          "transducer.driving.F_right", "transducer.s", "chain.v_mean"])
    m, preload = sim.get("cart.mass"), sim.get("chain.preload")
    s = df["transducer.s"].to_numpy()
    on_straight = (s > 1.0) & (s < track.s0[1] - 1.0) & (df["time"] > 1.0)
    assert on_straight.sum() > 100
    wheels = df.loc[on_straight, ["transducer.driving.F_left", "transducer.driving.F_right"]].to_numpy()
    assert wheels.mean() == pytest.approx(m * G / 2, rel=0.02)
    assert df.loc[on_straight, "transducer.joint.F_x"].mean() == pytest.approx(preload, rel=0.02)
    assert df["chain.v_mean"].iloc[-1] == pytest.approx(2.0, rel=0.01)


def test_energy_conserved_without_damping(sim):
    """Every e = 1, no motors, no rolling resistance: E drifts < 0.1 % in 10 s
    on the demo layout (every element type, inclines included)."""
    df = sim.simulate(10.0, 0.1, {"layout.name": "demo", **COAST, **ELASTIC}, ENERGY)
    E = df["energy.E_mech"].to_numpy()
    assert np.max(np.abs(E - E[0])) < 1e-3 * abs(E[0])
    assert df["energy.W_damping"].abs().max() < 1e-9


def test_energy_only_decreases_with_damping(sim):
    """With damping (no drive, no rolling) the energy never rises, and what it
    loses is exactly what the contact hysteresis dissipated."""
    df = sim.simulate(5.0, 0.05, {"layout.name": "demo", **COAST}, ENERGY, tolerance=1e-5)
    E, Wd = df["energy.E_mech"].to_numpy(), df["energy.W_damping"].to_numpy()
    assert np.all(np.diff(E) <= 1e-6 * abs(E[0]))
    assert E[-1] < E[0]
    balance = E + Wd - E[0]
    assert np.max(np.abs(balance)) < 1e-3 * (E[0] - E[-1]) + 1e-3


def test_energy_balance_with_drive_and_rolling(sim):
    """Driven and braked: E(t) - E(0) = W_motor - W_damping - W_rolling."""
    df = sim.simulate(5.0, 0.05, {"layout.name": "demo"}, ENERGY, tolerance=1e-5)
    lhs = df["energy.E_mech"] - df["energy.E_mech"].iloc[0]
    rhs = df["energy.W_motor"] - df["energy.W_damping"] - df["energy.W_rolling"]
    scale = df["energy.W_motor"].abs().max()
    assert scale > 10.0  # the drive really worked
    assert np.max(np.abs(lhs - rhs)) < 1e-3 * scale


def test_speed_control_settles_and_follows_step(sim):
    """The PI controller holds drive.v_ref within 1 % and follows a step set
    at a communication point."""
    def step_up(s, t):
        if abs(t - 8.0) < 1e-9:
            s.set("drive.v_ref", 2.5)
    df = sim.simulate(20.0, 0.05, {"layout.name": "demo", "drive.v_ref": 2.0}, ["chain.v_mean"],
                      on_step=step_up)
    v = df.set_index("time")["chain.v_mean"]
    assert v.loc[6.0:8.0].sub(2.0).abs().max() < 0.02
    assert v.loc[18.0:20.0].sub(2.5).abs().max() < 0.025
    assert v.loc[8.5] > 2.05  # it responded to the step


def test_incline_tension_gradient(sim, data_dir):
    """Climbing a ramp the front-joint tension grows by m g sin(gamma) per
    cart, and the driving wheels carry m g cos(gamma)."""
    layout = str(data_dir / "ramps.layout")
    track = load_track(layout)
    ramp0, ramp1 = track.s0[2], track.s0[3]  # the climbing straight
    gamma = float(track.incline(np.array([0.5 * (ramp0 + ramp1)]))[0])
    n = track.n_carts
    first = int(np.ceil(ramp0 / (track.length / n)))  # the first cart on the ramp at t = 0
    params = {"layout.name": layout, **COAST, "chain.transducer": first, "chain.v_init": 1.5,
              "drive.v_ref": 1.5, "chain.pretension": 0.02}
    df = sim.simulate(8.0, 0.01, params, ["transducer.joint.F_x", "transducer.driving.F_left",
                                          "transducer.driving.F_right", "transducer.s"])
    m, pitch = sim.get("cart.mass"), track.length / n
    s = df["transducer.s"].to_numpy()
    on = (s > ramp0 + 1.5) & (s < ramp1 - 1.5)
    assert on.sum() > 200
    slope = np.polyfit(s[on], df["transducer.joint.F_x"].to_numpy()[on], 1)[0]
    assert slope * pitch == pytest.approx(m * G * np.sin(gamma), rel=0.1)
    wheels = df.loc[on, ["transducer.driving.F_left", "transducer.driving.F_right"]].sum(axis=1).mean()
    assert wheels == pytest.approx(m * G * np.cos(gamma), rel=0.01)


def _curve_forces(sim, v: float) -> tuple[float, float]:
    """Mean inward steering-wheel force on the transducer cart in the oval's
    first curve (a left turn: the right wheel pushes inward) and the mean
    front-joint tension there."""
    track = load_track("oval")
    c0, c1 = track.s0[1], track.s0[2]
    params = {"layout.name": "oval", **COAST, "chain.v_init": v, "drive.v_ref": v,
              "track.guide_gap": -0.0003}
    stop = (c1 + 2.0) / v
    df = sim.simulate(stop, 0.005, params, ["transducer.steering.F_left", "transducer.steering.F_right",
                                            "transducer.joint.F_x", "transducer.s"])
    s = df["transducer.s"].to_numpy()
    inside = (s > c0 + 2.0) & (s < c1 - 2.0)
    assert inside.sum() > 50
    steer = (df["transducer.steering.F_right"] - df["transducer.steering.F_left"])[inside].mean()
    return float(steer), float(df["transducer.joint.F_x"][inside].mean())


def test_curve_lateral_force_grows_with_v_squared_over_r(sim):
    """In a horizontal curve of radius R the guides' inward force on a cart
    is what its circle needs, m v^2 / R, less the inward pull of the chain
    tension, T p / R. (In a closed chain T itself rises with speed: the
    centrifugal load compresses the guides and lengthens the chain's path, so
    both terms are needed to account for the steering force.)"""
    track = load_track("oval")
    R = 1.0 / float(np.linalg.norm(track.w[1]))
    pitch = track.length / track.n_carts
    speeds = np.array([0.8, 1.5, 2.2, 3.0])
    F, T = np.array([_curve_forces(sim, v) for v in speeds]).T
    A = np.column_stack([speeds ** 2 / R, -T * pitch / R])
    (alpha, beta), *_ = np.linalg.lstsq(A, F, rcond=None)
    assert alpha == pytest.approx(sim.get("cart.mass"), rel=0.15)
    assert beta == pytest.approx(1.0, rel=0.15)
    assert np.all(np.diff(F) > 0)  # more speed, more inward guide force
