"""A chain that starts from standstill (issue 17): placed anywhere on the track
(chain.s_start), relaxed into its static equilibrium (chain.relax_time), the
same equilibrium whatever the tunable values (the CoRs, mu_roll, the gains),
and kept as an FMU state that a later start restores instead of relaxing again."""
from __future__ import annotations

import numpy as np
import pytest

from lss_fmu.layouts import load_track
from lss_fmu.protocol import Protocol
from lss_fmu.runner import ChainSimulator, SimulationError
from lss_fmu.variables import FORCE_CHANNELS

REST = {"layout.name": "layout7", "chain.v_init": 0.0, "drive.v_ref": 0.0,
        "chain.relax_time": Protocol(name="start-up").relax_time(load_track("layout7").length),
        "chain.s_start": 17.3, "chain.pretension": 0.023}
OUT = FORCE_CHANNELS + ["chain.v_mean", "transducer.s"]


def test_the_relaxed_chain_stays_at_rest(sim):
    df = sim.simulate(1.0, 1 / 300, REST, outputs=OUT)
    F = df[FORCE_CHANNELS].to_numpy()
    assert np.abs(F - F[0]).max() < 2.0            # N: below the sensor noise (2-4 N)
    assert np.abs(df["chain.v_mean"]).max() < 1e-3  # m/s
    assert df["transducer.s"][0] == pytest.approx(17.3, abs=0.01)
    # without relaxing, the assembled chain rings and creeps
    raw = sim.simulate(1.0, 1 / 300, {**REST, "chain.relax_time": 0.0}, outputs=OUT)
    assert np.abs(raw[FORCE_CHANNELS].to_numpy() - raw[FORCE_CHANNELS].to_numpy()[0]).max() > 100.0


@pytest.mark.parametrize("layout", ["layout1", "layout5"])
def test_the_chain_at_rest_is_a_smooth_function_of_where_it_stands(sim, layout):
    """Half a millimetre further along the track, the relaxed chain's forces
    move by a smooth step: their second differences stay far below the jumps
    a relaxation decided by the state makes (kinetic damping: up to 1.3 and
    2.3 N over 8 mm on these layouts), so an objective has no local minima in
    the trigger point from the start alone."""
    T = Protocol(name="start-up").relax_time(load_track(layout).length)
    F = []
    for k in range(9):
        sim.start({"layout.name": layout, "chain.v_init": 0.0, "drive.v_ref": 0.0, "chain.relax_time": T,
                   "chain.s_start": 10.0 + 5e-4 * k})
        F.append([sim.get(n) for n in FORCE_CHANNELS])
    assert np.abs(np.diff(np.array(F), 2, axis=0)).max() < 0.05


@pytest.mark.parametrize("layout,tol", [("layout1", 1e-5), ("layout5", 1e-4)])
def test_the_chain_at_rest_does_not_depend_on_the_solver_tolerance(sim, layout, tol):
    """The identification runs at 1e-5, a user's default at 1e-4, the rig at
    1e-7: the chains at rest they start from agree to a tenth of the sensor's
    noise (relaxing at 1e-4 put the steps at the joints' stability limit, and
    the chains 0.3-0.8 N apart)."""
    p = {"layout.name": layout, "chain.v_init": 0.0, "drive.v_ref": 0.0, "chain.s_start": 12.0,
         "chain.relax_time": Protocol(name="start-up").relax_time(load_track(layout).length)}
    F = []
    for t in (tol, 1e-7):
        sim.start(p, tolerance=t)
        F.append([sim.get(n) for n in FORCE_CHANNELS])
    assert np.abs(np.subtract(*F)).max() < 0.2   # N; the noise is 2-4 N


def test_the_equilibrium_does_not_depend_on_the_tunable_values(sim):
    a = sim.simulate(0.01, 0.01, REST, outputs=OUT).to_numpy()[0]
    other = {"contact.e_JA": 0.3, "contact.e_SW": 0.8, "wheel.mu_roll": 0.03, "drive.Kp": 900.0, "drive.Ki": 50.0}
    with ChainSimulator() as fresh:       # a fresh instance: no state kept from the first
        b = fresh.simulate(0.01, 0.01, {**REST, **other}, outputs=OUT).to_numpy()[0]
    assert np.array_equal(a, b)


def test_a_kept_rest_state_gives_the_run_of_a_fresh_start(sim):
    """The second start restores the relaxed chain and sets its own CoRs on it:
    the run is the same, bit for bit, as a fresh instance relaxing from scratch."""
    ramp = {"drive.v_ref": lambda t: min(2.0 * t / 0.1, 2.0)}
    first = {"contact.e_SW": 0.6, "contact.e_RW": 0.4}
    second = {"contact.e_SW": 0.3, "contact.e_JA": 0.7, "drive.Kp": 700.0}
    sim.simulate(0.5, 1 / 300, {**REST, **first}, outputs=OUT, inputs=ramp)
    kept = sim.simulate(0.5, 1 / 300, {**REST, **second}, outputs=OUT, inputs=ramp)
    with ChainSimulator() as fresh:
        ref = fresh.simulate(0.5, 1 / 300, {**REST, **second}, outputs=OUT, inputs=ramp)
    assert np.array_equal(kept.to_numpy(), ref.to_numpy())
    assert len(sim._rest) >= 1


def test_relaxing_needs_a_chain_at_rest(sim):
    with pytest.raises(SimulationError, match="chain.relax_time"):
        sim.start({**REST, "chain.v_init": 2.0})
    with pytest.raises(SimulationError, match="chain.s_start"):
        sim.start({**REST, "chain.s_start": 1000.0})     # beyond the 65 m track
