"""The chain in a plant model (issue 52): an external drive whose motor
groups take their thrust from inputs, per-group outputs, the largest joint
force and the carts at the stations. Physics across the coupling: the chain
accelerates as Newton says under a thrust input; the groups sum to
drive.F_total; the outputs name what they say. Bad input is refused or
saturated with a logged message."""
from __future__ import annotations

import numpy as np
import pytest

from lss_fmu.runner import ChainSimulator, SimulationError
from lss_fmu.variables import N_GROUPS

GROUP_F = [f"drive.group{k}.F_total" for k in range(1, N_GROUPS + 1)]
GROUP_P = [f"drive.group{k}.P" for k in range(1, N_GROUPS + 1)]
OUT = ["chain.v_mean", "drive.F_total", "drive.P_total", "chain.joint.F_max", *GROUP_F, *GROUP_P]


def external(layout: str, groups: int, thrust: dict, **extra) -> dict:
    return {"layout.name": layout, "chain.v_init": 1.0, "drive.mode": 1, "drive.n_groups": groups,
            "wheel.mu_roll": 0.0, **{f"drive.group{k}.F": F for k, F in thrust.items()}, **extra}


def replay_after(s, vrs: list, steps: int, change) -> tuple:
    """Takes an FMU state, steps `steps` x 10 ms reading `vrs`, calls change(s) (inputs set after the state
    was taken), restores the serialized state and steps the same again: (first, second) readings."""
    state = s.fmu.getFMUstate()
    blob = s.fmu.serializeFMUstate(state)
    s.fmu.freeFMUstate(state)
    t_saved, runs = s.time, []
    for k in range(2):
        if k == 1:
            change(s)
            restored = s.fmu.deSerializeFMUstate(blob)
            s.fmu.setFMUstate(restored)
            s.fmu.freeFMUstate(restored)
            s.time = t_saved
        run = []
        for _ in range(steps):
            s.step(0.01)
            run.append(s.fmu.getReal(vrs))
        runs.append(run)
    return runs[0], runs[1]


def acceleration(df, t0: float = 0.1) -> float:
    """Mean acceleration after the first t0 s (the start's settling) by a straight line through v(t)."""
    keep = df["time"] >= t0
    return float(np.polyfit(df["time"][keep], df["chain.v_mean"][keep], 1)[0])


@pytest.mark.parametrize("layout, groups, thrust", [("layout7", 3, {1: 200.0, 2: 200.0, 3: 200.0}),
                                                    ("layout7", 2, {1: -150.0, 2: 100.0}),
                                                    ("layout1", 4, {1: 300.0, 2: 0.0, 3: 250.0, 4: 100.0})])
def test_the_chain_follows_newton_under_a_thrust_input(path_sim, layout, groups, thrust):
    """(a - a_free) M = the thrust the motors apply, a_free the coasting chain's deceleration (its own
    resistance: hysteresis of the contacts), M the chain's mass: within 1 %."""
    free = path_sim.simulate(1.0, 1 / 300, external(layout, groups, {}), outputs=OUT)
    M = path_sim.get("chain.n_carts") * path_sim.get("cart.mass")
    pushed = path_sim.simulate(1.0, 1 / 300, external(layout, groups, thrust), outputs=OUT)
    keep = pushed["time"] >= 0.1
    F = float(pushed["drive.F_total"][keep].mean())
    assert abs(F) > 100.0
    assert (acceleration(pushed) - acceleration(free)) * M == pytest.approx(F, rel=0.01)


def test_the_groups_sum_to_the_total_in_both_modes(path_sim):
    internal = path_sim.simulate(0.5, 1 / 300, {"layout.name": "layout1", "drive.n_groups": 8}, outputs=OUT)
    ext = path_sim.simulate(0.5, 1 / 300, external("layout1", 8, {k: 50.0 * k for k in range(1, 9)}), outputs=OUT)
    for df in (internal, ext):
        F = df[GROUP_F].to_numpy()
        assert np.abs(F.sum(axis=1) - df["drive.F_total"]).max() <= 1e-9 * np.abs(df["drive.F_total"]).max()
        assert (np.abs(F) > 0).sum(axis=1).max() >= 6           # the groups are spread over the track
        # the groups' power (plate thrust times tangential speed) is the motors' power to within 2 %
        assert df[GROUP_P].sum(axis=1).iloc[-1] == pytest.approx(df["drive.P_total"].iloc[-1], rel=0.02)
    # each group pushes with its own input: at the same start, group k's total scales with its input alone
    even = path_sim.simulate(0.02, 0.01, external("layout1", 8, dict.fromkeys(range(1, 9), 100.0)), outputs=OUT)
    ratio = ext[GROUP_F].iloc[0].to_numpy() / even[GROUP_F].iloc[0].to_numpy()
    assert ratio == pytest.approx([0.5 * k for k in range(1, 9)], rel=1e-12)


def test_the_largest_joint_force_and_its_cart(sim):
    p = external("layout7", 2, {1: 300.0, 2: 300.0})
    df = sim.simulate(0.3, 1 / 300, p, outputs=["chain.joint.F_max"])
    cart = int(sim.get("chain.joint.F_max_cart"))
    assert 0 <= cart < sim.get("chain.n_carts")
    # the same run with the transducer on that cart reads that force at its front joint
    j = sim.simulate(0.3, 1 / 300, {**p, "chain.transducer": cart},
                     outputs=["transducer.joint.F_x", "transducer.joint.F_y", "transducer.joint.F_z"])
    assert np.linalg.norm(j.iloc[-1, 1:].to_numpy()) == pytest.approx(df["chain.joint.F_max"].iloc[-1], rel=1e-9)


def test_the_station_cart_changes_as_carts_pass(sim):
    """At about 2 m/s, a cart passes a station every pitch / v seconds; the index steps down by one
    (cart i + 1 runs ahead of cart i)."""
    carts = []
    sim.simulate(1.5, 0.01, {"layout.name": "layout7", "station.induction.s": 12.0, "station.chute.s": 50.0},
                 outputs=["chain.v_mean"], on_step=lambda s, t: carts.append(int(s.get("station.induction.cart"))))
    n, pitch = int(sim.get("chain.n_carts")), sim.get("chain.pitch")
    changes = [(a, b) for a, b in zip(carts, carts[1:]) if a != b]
    assert all(b == (a - 1) % n for a, b in changes)
    assert len(changes) == pytest.approx(2.0 * 1.5 / pitch, abs=1.5)


def test_bad_coupling_input_is_refused_or_saturated_with_a_message(fmu_file):
    with ChainSimulator(fmu_file) as s:
        with pytest.raises(SimulationError, match="drive.group2.F"):
            s.start({**external("layout7", 2, {}), "drive.group2.F": float("nan")})
    with ChainSimulator(fmu_file) as s:
        with pytest.raises(SimulationError, match=r"drive.n_groups = 8 .* 7 motors"):
            s.start(external("layout7", 8, {}))
    with ChainSimulator(fmu_file) as s:
        with pytest.raises(SimulationError, match="station.chute.s"):
            s.start({"layout.name": "layout7", "station.chute.s": 1000.0})
    with ChainSimulator(fmu_file) as s:   # beyond the rating: saturated, and said
        s.simulate(0.05, 0.01, external("layout7", 1, {1: 5000.0}), outputs=["drive.F_total"])
        assert any("saturated to 400 N" in m for _, _, m in s.messages)
        F_sat = s.get("drive.F_total")
        s.simulate(0.05, 0.01, external("layout7", 1, {1: 400.0}), outputs=["drive.F_total"])
        assert s.get("drive.F_total") == pytest.approx(F_sat, rel=1e-12)
    with ChainSimulator(fmu_file) as s:   # external mode, thrust never set: said once
        s.simulate(0.05, 0.01, external("layout7", 1, {}), outputs=["drive.F_total"])
        assert sum("no drive.groupK.F input has been set" in m for _, _, m in s.messages) == 1


def test_an_fmu_state_replays_the_external_drive_bit_for_bit(fmu_file):
    with ChainSimulator(fmu_file) as s:
        s.start(external("layout7", 3, {1: 250.0, 2: -80.0, 3: 120.0}))
        vrs = [s.vr(c) for c in ("chain.v_mean", "drive.F_total", "drive.group2.F_total")]
        for _ in range(20):
            s.step(0.01)
        # drive.group2.F changed after the state was taken: the state restores it
        first, second = replay_after(s, vrs, 20, lambda sim: sim.set("drive.group2.F", 400.0))
        assert np.array_equal(first, second)


# --- items on carts ---------------------------------------------------------------------------

ITEM_OUT = ["chain.v_mean", "chain.items.mass", "energy.E_mech", "energy.E_items", "energy.W_motor",
            "energy.W_damping", "energy.W_rolling"]


def coasting(layout: str) -> dict:
    return {"layout.name": layout, "chain.v_init": 1.5, "drive.mode": 1, "wheel.mu_roll": 0.0, "drive.group1.F": 0.0}


def at(times: dict):
    """An on_step that sets the given inputs once the clock reaches each time."""
    def act(sim, t):
        for when, values in times.items():
            if abs(t - when) < 1e-9:
                for name, value in values.items():
                    sim.set(name, value)
    return act


@pytest.mark.parametrize("layout, cart, mass", [("layout7", 5, 30.0), ("layout7", 40, 80.0), ("layout1", 100, 50.0)])
def test_an_item_put_on_a_moving_cart_slows_the_chain_by_momentum(path_sim, layout, cart, mass):
    """An item arriving with no speed shares the chain's momentum: over the 0.1 s after it (the jolt
    running along the joints, averaged), the chain runs at M / (M + m) of the speed it has without it,
    within 0.3 %; taking the item off again changes no speed. (Later the item's weight on a slope
    moves the ratio: an external force, not the event.)"""
    ref = path_sim.simulate(0.5, 1 / 300, coasting(layout), outputs=ITEM_OUT)
    M = path_sim.get("chain.n_carts") * path_sim.get("cart.mass")
    df = path_sim.simulate(0.5, 1 / 300, coasting(layout), outputs=ITEM_OUT,
                           on_step=at({0.1: {"load1.cart": cart, "load1.mass": mass},
                                       0.3: {"load2.cart": cart, "load2.mass": 0.0}}))
    ratio = (df["chain.v_mean"] / ref["chain.v_mean"]).to_numpy()
    t = df["time"].to_numpy()

    def mean(a, b):
        return ratio[(t > a + 1e-9) & (t <= b + 1e-9)].mean()
    assert ratio[t <= 0.1 + 1e-9].max() == ratio[t <= 0.1 + 1e-9].min() == 1.0
    assert mean(0.11, 0.2) == pytest.approx(M / (M + mass), rel=0.003)
    assert mean(0.31, 0.4) == pytest.approx(mean(0.21, 0.3), rel=0.003)
    assert df["chain.items.mass"][t == t[t <= 0.2].max()].item() == mass and df["chain.items.mass"].iloc[-1] == 0.0


def test_the_energy_balance_holds_across_items(sim):
    """E_mech - E_items - W_motor + W_damping + W_rolling drifts no more with items coming and going on
    a driven chain than without them (the solver's own drift, about 0.35 J here): E_items is exactly the
    inelastic loss and the items' weight."""
    def drift(events):
        df = sim.simulate(0.8, 1 / 300, {"layout.name": "layout7"}, outputs=ITEM_OUT, on_step=at(events))
        balance = df["energy.E_mech"] - df["energy.E_items"] - df["energy.W_motor"] + df["energy.W_damping"] + \
            df["energy.W_rolling"]
        return float(balance.iloc[-1] - balance.iloc[0]), df
    plain, _ = drift({})
    moved, df = drift({0.1: {"load1.cart": 3, "load1.mass": 40.0}, 0.3: {"load1.cart": 20, "load1.mass": 25.0},
                       0.5: {"load2.cart": 3, "load2.mass": 0.0}})
    assert np.ptp(df["energy.E_items"]) > 100.0        # J moved by the items
    assert abs(moved - plain) < 0.05
    assert df["chain.items.mass"].iloc[-1] == 25.0


def test_items_at_the_start_ride_from_the_start(sim):
    df = sim.simulate(0.2, 0.01, {"layout.name": "layout7", "load1.cart": 7, "load1.mass": 50.0},
                      outputs=["chain.items.mass", "energy.E_items"])
    assert df["chain.items.mass"].iloc[0] == 50.0 and df["energy.E_items"].iloc[-1] == 0.0


def test_bad_item_input_is_refused_naming_it(fmu_file):
    with ChainSimulator(fmu_file) as s:
        with pytest.raises(SimulationError, match=r"load1.cart = 52 is invalid: the chain has 52 carts"):
            s.start({"layout.name": "layout7", "load1.cart": 52, "load1.mass": 5.0})
    for name, value in (("load2.mass", 2000.0), ("load2.mass", -1.0), ("load1.mass", float("nan")),
                        ("load1.cart", -2)):
        with ChainSimulator(fmu_file) as s:
            s.start({"layout.name": "layout7"})
            s.step(0.01)
            with pytest.raises(SimulationError, match=name.replace(".", r"\.")):
                s.set(name, value)
    with ChainSimulator(fmu_file) as s:     # in Step Mode too, and the refused value leaves the chain as it was
        s.start({"layout.name": "layout7"})
        s.step(0.01)
        with pytest.raises(SimulationError, match="load2.cart = 99 is invalid"):
            s.set("load2.cart", 99)
        s.step(0.01)
        assert s.get("chain.items.mass") == 0.0


def test_an_fmu_state_keeps_the_items(fmu_file):
    with ChainSimulator(fmu_file) as s:
        s.start({"layout.name": "layout7", "load1.cart": 4, "load1.mass": 20.0})
        vrs = [s.vr(c) for c in ("chain.v_mean", "chain.items.mass", "energy.E_items", "transducer.joint.F_x")]
        s.step(0.05)
        s.set("load2.cart", 9)
        s.set("load2.mass", 35.0)
        s.step(0.05)
        # the item taken off after the state was taken: the state puts it back
        first, second = replay_after(s, vrs, 10, lambda sim: sim.set("load2.mass", 0.0))
        assert np.array_equal(first, second) and first[-1][1] == 55.0
