"""Synthetic release-transient measurements with undeclared effects (issue 7).

Used by the close-loop tests, `make demo` and the optimiser benchmark. A case
is the release transient of layout 7 (the window where the chain is
not yet chaotic, docs/identification.md): the FMU at a known truth with one
or more effects switched on (parameters drawn from a seed by the virtual
transducer cart's own draw, lss_fmu.rig_effects), plus the sensor model's
noise and its in-specification offsets, or an artefact outside the
catalogue. The problem given to the loop declares nothing of it: the four
CoRs are free, everything else at the truth.
"""
from __future__ import annotations

import math

import numpy as np

from .attribution import simulate_with
from lss_fmu.design import CORS
from lss_fmu.runner import LazySimulator

from ..objective.problem import IdentificationProblem, tare_of
from lss_fmu.sensor import NOISE_STD, OFFSET_STD
from lss_fmu.variables import FORCE_CHANNELS
from lss_fmu.rig_effects import add_to_forces
from lss_fmu import rig_effects
from lss_fmu.layouts import load_track

LAYOUT = "layout7"
TRUTH = {"contact.e_JA": 0.46, "contact.e_JR": 0.558, "contact.e_SW": 0.351, "contact.e_RW": 0.645,
         "drive.v_ref": 2.0, "chain.pretension": 0.03, "wheel.mu_roll": 0.015, "trigger.s_M": 0.05,
         "drive.Kp": 500.0, "drive.Ki": 200.0}
FIXED = {"track.guide_gap": -0.0003}
WINDOW = 1.0        # s
SETTLE = 0.02       # s
PITCH = 1.25        # m, cart i starts at about i * PITCH


def transducer_before(s_target: float, lead: float = 0.5, sim=None) -> tuple:
    """(cart index, trigger s_M) so that the transducer cart passes s_target
    early in the window: the cart about `lead` behind it, triggered 5 cm
    after its assembled position (read from the FMU: `sim`, a ChainSimulator,
    by default a new one)."""
    i = int(math.floor((s_target - lead) / PITCH)) % 52
    sim = sim or LazySimulator()()
    sim.start({"layout.name": LAYOUT, "chain.transducer": i, **FIXED})
    return i, float(sim.get("transducer.s")) + 0.05


def release_problem(window: float = 0.6, s_m: float = 0.3, noise_seed: int = 1,
                    sim: LazySimulator | None = None) -> IdentificationProblem:
    """Layout 7, LW, the first `window` s after the trigger at `s_m`, right behind
    the start: the model at the truth (Table 3, row 1) plus the sensor model's
    noise, no offsets, no tare. The recovery tests and the optimiser benchmark
    identify the four CoRs on it."""
    times = np.arange(0, window, 1 / 300)
    truth = {**TRUTH, "trigger.s_M": s_m}
    x0 = {**truth, **{k: 0.55 for k in CORS}}
    p = IdentificationProblem(np.zeros((len(times), 7)), times, LAYOUT, "LW", {k: (0.2, 0.9) for k in CORS},
                              fixed=FIXED, free=CORS, x0=x0, settle=SETTLE, sim=sim or LazySimulator())
    clean = p.simulate([truth[k] for k in CORS])
    noise = np.random.default_rng(noise_seed).normal(size=clean.shape) * [NOISE_STD[c] for c in FORCE_CHANNELS]
    p.samples = clean + noise
    return p


def cart_trigger(cart: int, sim=None, after: float = 0.05) -> float:
    """The trigger point s_M just ahead of cart `cart`'s assembled position
    (`after` m), so that it passes s_M right after the release."""
    sim = sim or LazySimulator()()
    sim.start({"layout.name": LAYOUT, "chain.transducer": int(cart), **FIXED})
    return float(sim.get("transducer.s")) + after


def make_problem(effect_params: dict, seed: int, *, transducer: int = 0, s_m: float = 0.05,
                 artefact: dict | None = None, offsets: bool = True, sim: LazySimulator | None = None,
                 artefacts: dict | None = None, window: float = WINDOW) -> tuple:
    """(problem, truth_x): the measurement simulated with `effect_params`, the
    problem without them. `artefacts`: disturbances outside the catalogue as
    lss_fmu.rig_effects draws them ({name: definition}: interference,
    crosstalk, clock_drift), added to the clean forces (the clock: the forces
    simulated at the true times t / (1 + eps))."""
    times = np.arange(0.0, window, 1.0 / 300.0)
    x0 = {**TRUTH, "trigger.s_M": s_m, **{k: 0.55 for k in CORS}}
    fixed = {**FIXED, "chain.transducer": transducer}
    p = IdentificationProblem(np.zeros((len(times), 7)), times, LAYOUT, "LW", {k: (0.2, 0.9) for k in CORS},
                              fixed=fixed, free=CORS, x0=x0, settle=SETTLE, name=f"case{seed}", tare=tare_of(),
                              sim=sim or LazySimulator())
    truth = np.array([TRUTH[k] for k in CORS])
    artefacts = dict(artefacts or {})
    if "clock_drift" in artefacts:
        import dataclasses
        clean = simulate_with(dataclasses.replace(p, times=times / (1.0 + float(artefacts["clock_drift"]["eps"]))),
                              truth, effect_params)
    else:
        clean = simulate_with(p, truth, effect_params)
    for name in ("interference", "crosstalk"):
        if name in artefacts:
            clean, _ = add_to_forces(times, clean, name, artefacts[name])
    rng = np.random.default_rng([seed, 99])
    noisy = clean + rng.normal(size=clean.shape) * [NOISE_STD[c] for c in FORCE_CHANNELS]
    if offsets:  # the transducer's own zero error, within its specification
        noisy = noisy + rng.normal(size=7) * [OFFSET_STD[c] for c in FORCE_CHANNELS]
    if artefact:
        j = FORCE_CHANNELS.index(artefact["channel"])
        t0, width, amp = artefact["t"], artefact["width"], artefact["amplitude"]
        u = (times - t0) / width
        noisy[:, j] += amp * np.where(np.abs(u) < 0.5, 0.5 * (1 + np.cos(2 * np.pi * u)), 0.0)
    p.samples = noisy
    return p, truth


def effect_case(effects, seed: int, artefact: dict | None = None, *, params: dict | None = None,
                artefacts=None, transducer: int | None = None, lead: float = 0.5) -> tuple:
    """(problem, FMU parameters of the effects): the effects drawn by the virtual
    transducer cart (lss_fmu.rig_effects) from `seed` (or given as `params`),
    switched on in the measurement only. `artefacts`: names of disturbances
    outside the catalogue drawn by the rig from the seed (or {name:
    definition}). `transducer`: the transducer cart (default 0, or the one
    `lead` m before a bump), triggered just after the release."""
    if params is None:
        params = rig_effects.draw_effects(list(effects), seed, LAYOUT) if effects else {}
    if artefacts and not isinstance(artefacts, dict):
        artefacts = rig_effects.draw_artefacts(list(artefacts), seed, float(load_track(LAYOUT).length))
    sim = LazySimulator()
    kw = {}
    if "effects.track_bump.s" in params and transducer is None:  # the transducer cart passes the joint in the window
        kw["transducer"], kw["s_m"] = transducer_before(params["effects.track_bump.s"], lead=lead, sim=sim())
    elif transducer is not None:
        kw["transducer"], kw["s_m"] = int(transducer), cart_trigger(int(transducer), sim=sim())
    problem, _ = make_problem(params, seed, artefact=artefact, sim=sim, artefacts=artefacts, **kw)
    return problem, params
