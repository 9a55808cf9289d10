"""The virtual transducer cart: the paper's 22 measurements, synthesised.

Three sets (docs/measurements.md):

* `recovery`: the truth is the model itself: contact law LW, the CoRs of the
  paper's Table 3 (measurement k gets row k), the layout-dependent values
  (v_s, d, mu_d, s_M, K_P, K_I) drawn near their nominal values from the seed,
  everything else at the FMU's defaults. Identification with LW should find
  these values again.
* `field`: the same test plan and draws, but as a real sorter would give them:
  the contact law is GZ (the exact Gonthier/Zhang-Sharf relation, not one of
  the candidates HC, HW, LW, LN), the carts of each sorter are slightly
  heavier or lighter than their type's nominal mass, the guide play differs
  from nominal, and the track deviates slightly from its drawing (curve and
  vertical-curve radii and straight lengths perturbed, the loop re-closed).
* `drawn`: `recovery` with other contacts: every CoR of every measurement
  drawn uniformly over the CoR box from the seed, so a method tuned on Table
  3 is checked on values it has never seen.

Each measurement is simulated by the FMU at the sensor model's internal rate
(1200 Hz), passed through the sensor model (lss_fmu.sensor) and written as a
measurement folder (lss_fmu.measurement). The truth goes to DIR/answers/,
which identification never reads.

    DIR/set.json               the set: name, seed, FMU hash, generation times
    DIR/mNN/                   measurement folders, NN the measurement's number (samples.csv, meta.json)
    DIR/answers/mNN/truth.json the truth of each measurement
    DIR/answers/tracks/*.layout  the as-built tracks of the field set
    DIR/survey/mNN.json        the field set: what a survey of the sorter gives (lss_fmu.survey: its
                               as-built track in DIR/survey/tracks/, mass factor, guide gap)
    DIR/fmu/LSSChain-<sha>.fmu the FMU that generated the set

`generate_set(...)` runs measurements in parallel (one ChainSimulator per
worker process) with a progress bar; `lss rig` is its command line
(lss_fmu.rig_cli). Every set can carry undeclared effects of the FMU's
catalogue and an artefact outside it (lss_fmu.rig_effects): in the FMU
parameters and the truth, never in meta.json.
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import hashlib
import json
import math
import os
import shutil
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional, Sequence, Union

import numpy as np

from . import design
from . import measurement as M
from . import rig_effects as E
from . import survey
from .atomic import locked, write_atomic, write_json_atomic
from .layout_format import CURVE, SPIRAL, STRAIGHT, VCURVE, format_layout
from .layouts import NOMINAL_PRETENSION, TABLE2, load_track
from .protocol import NAMES as PROTOCOLS
from .protocol import Protocol
from .sensor import CHANNELS, S_CHANNEL, SensorModel
from .triggered import arriving_cart
from .variables import BY_NAME, CONTACT_MODELS

SETS = ("recovery", "field", "drawn")
DEFAULT_SEED = 20120901
SETTLE_TIME = 4.0             # s: the trigger is armed after this (start transient)
ARRIVAL_DELAY = (1.0, 2.0)    # s after arming: when the transducer cart reaches s_M (uniform)
END_MARGIN = 1.0              # s simulated after the expected end of the lap
TRANSIENT_RECORD = 4.0        # s logged in a transient protocol (start-up, speed step, stop)
TRANSIENT_TOLERANCE = 1e-7    # the rig's solver tolerance there: ten times finer than identification's
REST_LEAD = 0.5               # s of standstill the logger sees before a start command (filter, wheel counters)
SPEED_MARGIN = 0.03           # relative: the lap may take this much longer than L / v_s

# Table 2 order: measurements 1..22 are numbered layout by layout
MEASUREMENTS_PER_LAYOUT = [("layout1", 4), ("layout2", 4), ("layout3", 3), ("layout4", 1),
                           ("layout5", 6), ("layout6", 1), ("layout7", 3)]

# The paper's Table 3 (LW): e_JA, e_JR, e_SW, e_RW of measurement k (row k)
TABLE3 = [
    (0.460, 0.558, 0.351, 0.645), (0.448, 0.279, 0.674, 0.576), (0.740, 0.443, 0.439, 0.483),
    (0.501, 0.500, 0.501, 0.500), (0.538, 0.509, 0.500, 0.741), (0.716, 0.369, 0.387, 0.575),
    (0.795, 0.202, 0.493, 0.811), (0.582, 0.322, 0.540, 0.444), (0.590, 0.310, 0.578, 0.623),
    (0.441, 0.237, 0.489, 0.515), (0.433, 0.202, 0.732, 0.370), (0.597, 0.409, 0.544, 0.470),
    (0.783, 0.531, 0.513, 0.361), (0.552, 0.666, 0.563, 0.597), (0.353, 0.271, 0.321, 0.200),
    (0.425, 0.573, 0.519, 0.474), (0.584, 0.889, 0.351, 0.219), (0.251, 0.767, 0.234, 0.564),
    (0.504, 0.236, 0.572, 0.534), (0.675, 0.473, 0.358, 0.825), (0.714, 0.590, 0.460, 0.311),
    (0.609, 0.737, 0.318, 0.479),
]
COR_NAMES = design.COR_SYMBOLS

# The test plan: nominal speed (m/s) and pretension (factor on the layout's
# calibrated pretension) of each measurement, as a test engineer would vary them.
TEST_PLAN = {
    1: (1.5, 1.0), 2: (2.0, 1.0), 3: (2.5, 1.25), 4: (3.0, 0.8),
    5: (1.5, 1.25), 6: (2.0, 0.8), 7: (2.5, 1.0), 8: (3.0, 1.25),
    9: (2.0, 1.0), 10: (2.5, 1.25), 11: (3.0, 0.8),
    12: (2.0, 1.0),
    13: (1.5, 0.8), 14: (1.5, 1.25), 15: (2.0, 1.0), 16: (2.5, 0.8), 17: (2.5, 1.25), 18: (3.0, 1.0),
    19: (2.0, 1.0),
    20: (1.5, 1.0), 21: (2.0, 1.25), 22: (3.0, 0.8),
}

# Spread of the truth around the nominal values
V_REL_STD, V_REL_MAX = 0.01, 0.03          # speed: the sorter's set point vs the real speed
D_REL_STD, D_REL_MAX = 0.08, 0.25          # pretension: as set vs as measured by hand
MU_LOG_STD, MU_RANGE = 0.2, (0.6, 1.6)     # rolling resistance (factor on 0.015)
SM_STD, SM_MAX = 0.10, 0.30                # trigger point: m
K_LOG_STD, K_RANGE = 0.25, (0.5, 2.0)      # PI gains (factor on the FMU defaults)

# Field set: what a real sorter adds (per layout)
FIELD_CONTACT_LAW = "GZ"
FIELD_MASS_STD, FIELD_MASS_MAX = 0.02, 0.05          # cart.mass_factor - 1
FIELD_GAP_STD, FIELD_GAP_RANGE = 1.0e-4, (3e-4, 8e-4)  # track.guide_gap, m (nominal 0.5 mm)
FIELD_CURVE_RADIUS_STD = 0.005      # relative, horizontal curves and spirals
FIELD_VCURVE_RADIUS_STD = 0.02      # relative, vertical curves
FIELD_STRAIGHT_STD = 0.003          # m, every straight that is not solved for closure
# FMU parameters the field set would use if the FMU had them (issue 7 effects):
# none are set unless present in the FMU and listed here by the lead.
FIELD_EXTRA_FMU = {}


def rig_protocol(name: str, v_nominal: float) -> Protocol:
    """How the virtual test engineer runs each protocol: a start at full thrust
    (the set point steps from 0 to v_s), a speed step from 3/4 of the nominal
    set point and a stop with the set point dropped to 0 (the drive brakes),
    both 1 s after the photocell, and a start-stop: the start, braked 1 s
    after the start command."""
    if name == "steady":
        return Protocol("steady", run_in=SETTLE_TIME)
    if name == "start-up":
        return Protocol("start-up", ramp_time=0.0)
    if name == "speed-step":
        return Protocol("speed-step", step_time=1.0, v_from=round(0.75 * v_nominal, 3), run_in=SETTLE_TIME)
    if name == "stop":
        return Protocol("stop", step_time=1.0, run_in=SETTLE_TIME)
    if name == "start-stop":
        return Protocol("start-stop", step_time=1.0, ramp_time=0.0)
    raise ValueError(f"unknown protocol {name!r} (known: {', '.join(PROTOCOLS)})")


def numbering() -> dict:
    """Measurement number -> layout (Table 2 order)."""
    out, k = {}, 1
    for layout, n in MEASUREMENTS_PER_LAYOUT:
        for _ in range(n):
            out[k] = layout
            k += 1
    return out


NUMBERING = numbering()
ALL_NUMBERS = tuple(sorted(NUMBERING))


def folder_name(number: int) -> str:
    return f"m{number:02d}"


def parse_numbers(text: Optional[str]) -> list:
    """'1,2,19-22' -> [1, 2, 19, 20, 21, 22]; None or 'all' -> all 22."""
    if text is None or text.strip().lower() in ("", "all"):
        return list(ALL_NUMBERS)
    out = []
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part:
                a, b = (int(x) for x in part.split("-", 1))
                if a > b:
                    raise ValueError
                out.extend(range(a, b + 1))
            else:
                out.append(int(part))
        except ValueError:
            raise ValueError(f"--measurements: {part!r} is not a number or a range a-b") from None
    bad = [n for n in out if n not in NUMBERING]
    if bad:
        raise ValueError(f"--measurements: no measurement {', '.join(map(str, bad))} (there are 1-22)")
    return sorted(set(out))


def _layout_index(layout: str) -> int:
    return [lay for lay, _ in MEASUREMENTS_PER_LAYOUT].index(layout) + 1


def trigger_point_nominal(layout: str) -> float:
    """The photocell's nominal position: the middle of the longest level straight, to 0.1 m."""
    tr = load_track(layout)
    best, s_best = -1.0, 0.0
    for i, e in enumerate(tr.spec.elements):
        if e.kind == STRAIGHT and abs(tr.entry_incline[i]) < 1e-9 and e.length > best:
            best, s_best = e.length, tr.s0[i] + 0.5 * e.length
    return round(s_best, 1)


def _clip(x, lo, hi):
    return float(min(max(x, lo), hi))


@dataclass
class Case:
    """Everything that defines one synthetic measurement."""
    set: str
    number: int
    seed: int
    layout: str                # built-in layout (what meta.json says)
    layout_fmu: str            # what the FMU runs (built-in name or as-built track file)
    track_length: float
    n_carts: int
    speed_nominal: float
    pretension_nominal: float
    pretension_factor: float
    s_M_nominal: float
    truth: dict                # design variables: v_s, d, mu_d, s_M, K_P, K_I
    cor: dict                  # e_JA, e_JR, e_SW, e_RW
    contact_law: str
    fmu_params: dict           # every FMU parameter the run sets
    field: dict                # field-set deviations (empty for recovery)
    transducer: int
    arrival_time: float        # expected passage of s_M
    stop_time: float           # simulation end
    # undeclared effects (lss_fmu.rig_effects): in fmu_params and the truth, never in meta.json
    effects: dict = dataclasses.field(default_factory=dict)     # name -> drawn parameters and details
    artefacts: dict = dataclasses.field(default_factory=dict)   # name -> definition (sensor stage)
    effect_seed: Optional[int] = None
    protocol: Protocol = dataclasses.field(default_factory=Protocol)
    repeat: int = 0            # the k-th run of a from-rest protocol: the chain parked elsewhere, another noise draw

    @property
    def id(self) -> str:
        return f"{self.set}-{folder_name(self.number)}" + (f"-r{self.repeat}" if self.repeat else "")

    @property
    def cost(self) -> float:
        """Cart-seconds to simulate (for scheduling and estimates)."""
        return self.n_carts * self.stop_time


def _as_built_track(layout: str, seed: int, out_dir: Optional[Path]) -> tuple:
    """The field set's as-built track of a layout: the design's radii and
    straights perturbed (seeded), the loop re-closed by the design's closing
    straights. Returns (path or None, description)."""
    from .layout_design import DESIGNS, Design, solve
    design = next(d for d in DESIGNS if d.name == layout)
    rng = np.random.default_rng([seed, 2000 + _layout_index(layout)])
    items, changes = [], []
    # without a lateral closing straight ('y') the plan closes only if the curves keep
    # their proportions: then one common radius factor for all of them
    common = None if any(it.var == "y" for it in design.items) else rng.normal(0.0, FIELD_CURVE_RADIUS_STD)
    for it in design.items:
        it2 = dataclasses.replace(it)
        if it.kind in (CURVE, SPIRAL):
            dev = rng.normal(0.0, FIELD_CURVE_RADIUS_STD) if common is None else common
            it2.radius = float(it.radius * (1.0 + dev))
        elif it.kind == VCURVE:
            it2.radius = float(it.radius * (1.0 + rng.normal(0.0, FIELD_VCURVE_RADIUS_STD)))
        elif it.kind == STRAIGHT and it.var is None:
            it2.length = float(it.length + rng.normal(0.0, FIELD_STRAIGHT_STD))
        items.append(it2)
    d2 = Design(f"{layout}-as-built", design.title, design.carts, design.motors, design.wheel,
                design.coupling, items)
    spec = solve(d2)
    for e in spec.elements:  # plain floats, so the file reads back exactly
        e.length, e.radius, e.angle, e.rise = float(e.length), float(e.radius), float(e.angle), float(e.rise)
    nominal = load_track(layout).spec.elements
    for k, (a, b) in enumerate(zip(nominal, spec.elements)):
        if a.kind == STRAIGHT:
            changes.append(abs(b.length - a.length))
        else:
            changes.append(abs(b.radius - a.radius))
    desc = {"max_straight_change_m": float(max(c for c, e in zip(changes, nominal) if e.kind == STRAIGHT)),
            "max_radius_change_m": float(max((c for c, e in zip(changes, nominal) if e.kind != STRAIGHT),
                                             default=0.0)),
            "curve_radius_rel_std": FIELD_CURVE_RADIUS_STD, "vcurve_radius_rel_std": FIELD_VCURVE_RADIUS_STD,
            "straight_std_m": FIELD_STRAIGHT_STD}
    if out_dir is None:
        return None, desc, spec
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{layout}.layout"
    text = format_layout(spec, comment=f"As-built track of {layout} for the field set (seed {seed}): the "
                                       f"design's radii and straights perturbed, the loop re-closed.\n"
                                       f"Written by lss_fmu.rig; part of the answers, not of the measurements.")
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path, desc, spec


def make_case(set_name: str, number: int, seed: int = DEFAULT_SEED, answers_dir: Optional[Path] = None,
              lap_seconds: Optional[float] = None, extra_params: Optional[Mapping] = None,
              effects: Sequence[str] = (), effect_seed: Optional[int] = None,
              artefacts: Sequence[str] = (), protocol: str = "steady", repeat: int = 0,
              effect_values: Optional[Mapping[str, float]] = None) -> Case:
    """The definition of measurement `number` of a set, drawn from the seed,
    measured with `protocol` (rig_protocol).

    `effect_values`: FMU values of the drawn `effects` set instead of drawn
    (rig_effects.set_values: an effect's size for a benchmark).

    `repeat` k > 0: the same sorter (every drawn value the same) started from
    rest once more, after the chain stopped somewhere else: another parking
    position of the transducer cart and another draw of the sensor's noise
    and offsets. Only for the protocols that start from rest.

    The draws of the layout-dependent values depend only on (seed, layout) and
    (seed, number), not on the set or on which other measurements are made, so
    the recovery and field sets share them and any subset gives the same
    measurements as the full run.

    `effects` (names from rig_effects.CATALOGUE) are switched on in the FMU
    parameters, `artefacts` (rig_effects.ARTEFACTS) added in the sensor stage,
    both drawn from (effect_seed, default `seed`; layout): every measurement on
    a layout gets the same ones. meta.json says nothing about them."""
    effects, artefacts = E.parse_effects(effects), E.parse_artefacts(artefacts)
    if set_name not in SETS:
        raise ValueError(f"unknown set {set_name!r} (known: {', '.join(SETS)})")
    if number not in NUMBERING:
        raise ValueError(f"no measurement {number} (there are 1-22)")
    layout = NUMBERING[number]
    v_nom, d_factor = TEST_PLAN[number]
    d_nom = round(NOMINAL_PRETENSION[layout] * d_factor, 5)
    s_M_nom = trigger_point_nominal(layout)
    kp_nom, ki_nom = float(BY_NAME["drive.Kp"].start), float(BY_NAME["drive.Ki"].start)
    mu_nom = float(BY_NAME["wheel.mu_roll"].start)
    # per layout: the trigger mark and the drive (same for every measurement on the layout)
    rl = np.random.default_rng([seed, 1000 + _layout_index(layout)])
    s_M = s_M_nom + _clip(rl.normal(0.0, SM_STD), -SM_MAX, SM_MAX)
    kp = kp_nom * _clip(math.exp(rl.normal(0.0, K_LOG_STD)), *K_RANGE)
    ki = ki_nom * _clip(math.exp(rl.normal(0.0, K_LOG_STD)), *K_RANGE)
    # per measurement: speed, pretension, rolling resistance, arrival
    rm = np.random.default_rng([seed, number])
    v = v_nom * (1.0 + _clip(rm.normal(0.0, V_REL_STD), -V_REL_MAX, V_REL_MAX))
    d = d_nom * (1.0 + _clip(rm.normal(0.0, D_REL_STD), -D_REL_MAX, D_REL_MAX))
    mu = mu_nom * _clip(math.exp(rm.normal(0.0, MU_LOG_STD)), *MU_RANGE)
    arrival = SETTLE_TIME + float(rm.uniform(*ARRIVAL_DELAY))
    truth = {"v_s": v, "d": d, "mu_d": mu, "s_M": s_M, "K_P": kp, "K_I": ki}
    cor = dict(zip(COR_NAMES, TABLE3[number - 1]))
    if set_name == "drawn":
        # contacts the identification has never been tuned on: each CoR uniform over the box it searches
        rc = np.random.default_rng([seed, number, 5])
        cor = {k: round(float(rc.uniform(*design.COR_BOUNDS)), 3) for k in COR_NAMES}

    field, layout_fmu, geometry = {}, layout, None
    law = "LW"
    params = {}
    if set_name == "field":
        law = FIELD_CONTACT_LAW
        rf = np.random.default_rng([seed, 3000 + _layout_index(layout)])
        mass = 1.0 + _clip(rf.normal(0.0, FIELD_MASS_STD), -FIELD_MASS_MAX, FIELD_MASS_MAX)
        gap = _clip(float(BY_NAME["track.guide_gap"].start) + rf.normal(0.0, FIELD_GAP_STD), *FIELD_GAP_RANGE)
        path, desc, geometry = _as_built_track(layout, seed, None if answers_dir is None else answers_dir / "tracks")
        if path is not None:
            layout_fmu = str(Path(path).resolve())
        field = {"cart.mass_factor": mass, "track.guide_gap": gap, "as_built_track": desc,
                 "as_built_file": None if path is None else f"answers/tracks/{layout}.layout"}
        params.update({"cart.mass_factor": mass, "track.guide_gap": gap})
        params.update(FIELD_EXTRA_FMU)
    track = load_track(layout_fmu if set_name == "field" and layout_fmu != layout else layout)
    L, N = float(track.length), int(track.n_carts)
    proto = rig_protocol(protocol, v_nom)
    if isinstance(repeat, bool) or not isinstance(repeat, int) or repeat < 0:
        raise ValueError(f"repeat {repeat!r}: must be a whole number, 0 or more")
    if repeat and not proto.from_rest:
        raise ValueError(f"repeat {repeat}: only a protocol that starts from rest (start-up, start-stop) can be "
                         f"repeated with the chain parked elsewhere, not {protocol!r}")
    if proto.from_rest:
        # the chain stopped wherever it stopped: the transducer cart's axle is parked at s_M, read off the
        # track marks to 0.1 m (s_M_nom); cart 0 of the FMU is the transducer (the carts are alike)
        rp = np.random.default_rng([seed, number, 7] + ([repeat] if repeat else []))
        s_M_nom = round(float(rp.uniform(0.0, L)), 1) % L
        s_M = (s_M_nom + _clip(rp.normal(0.0, SM_STD), -SM_MAX, SM_MAX)) % L
        truth["s_M"] = s_M
        idx, arrival = 0, 0.0
        log = TRANSIENT_RECORD if lap_seconds is None else float(lap_seconds)
        stop = log + END_MARGIN
        start = {"chain.v_init": 0.0, "chain.relax_time": proto.relax_time(L), "chain.s_start": s_M,
                 "drive.v_ref": 0.0}
    else:
        # the transducer cart: the one that reaches s_M about `arrival` s after the start
        idx, arrival = arriving_cart(L, N, s_M, proto.v_before(v, v_nom), arrival, earliest=SETTLE_TIME + 0.3)
        full = (L / v) * (1.0 + SPEED_MARGIN) if not proto.transient else TRANSIENT_RECORD
        log = full if lap_seconds is None else float(lap_seconds)
        stop = arrival + log + END_MARGIN
        start = {"drive.v_ref": proto.v_before(v, v_nom)}
    params.update({
        "layout.name": layout_fmu,
        "contact.model": CONTACT_MODELS[law],
        **{f"contact.{k}": val for k, val in cor.items()},
        "chain.pretension": d, "wheel.mu_roll": mu, "drive.Kp": kp, "drive.Ki": ki, "drive.v_ref": v,
        "chain.transducer": idx, **start,
    })
    eff, arts, eseed = {}, {}, None
    if effects or artefacts:
        from .track_geometry import Track
        eseed = seed if effect_seed is None else int(effect_seed)
        geom = track if geometry is None else Track(geometry)   # the track the FMU runs (joints of the as-built)
        eff = E.effects_truth(effects, eseed, geom, transducer=idx, stream=_layout_index(layout),
                              pretension=NOMINAL_PRETENSION[layout])
        if effect_values:
            eff = E.set_values(eff, effect_values)
        for d in eff.values():
            params.update(d["parameters"])
        arts = E.draw_artefacts(artefacts, eseed, L, stream=_layout_index(layout), avoid_s=s_M)
    elif effect_values:
        raise ValueError(f"effect values {', '.join(sorted(effect_values))} given, but no effect is switched on")
    if extra_params:
        params.update(extra_params)
    return Case(set_name, number, seed, layout, layout_fmu, L, N, v_nom, d_nom, d_factor, s_M_nom, truth, cor,
                law, params, field, idx, arrival, stop, eff, arts, eseed, proto, repeat)


def meta_for(case: Case, sensor: SensorModel, n_samples: int, full_lap: bool) -> dict:
    """What the test engineer writes down (no truth in it)."""
    spec = TABLE2[case.layout]
    date = _dt.date(2011, 3, 7) + _dt.timedelta(days=7 * (_layout_index(case.layout) - 1)
                                                + case.number % 5)
    meta = {
        "format_version": M.FORMAT_VERSION,
        "id": case.id,
        "number": case.number,
        "set": case.set,
        "layout": case.layout,
        "wheel_type": spec["wheel"],
        "coupling_type": spec["coupling"],
        "speed_nominal": case.speed_nominal,
        "pretension_nominal": case.pretension_nominal,
        "sample_rate": sensor.sample_rate,
        "trigger_point": case.s_M_nominal,
        "date": date.isoformat(),
        "mu_roll_nominal": float(BY_NAME["wheel.mu_roll"].start),
        "Kp_nominal": float(BY_NAME["drive.Kp"].start),
        "Ki_nominal": float(BY_NAME["drive.Ki"].start),
        "transducer_cart": "virtual transducer cart (lss_fmu.rig)",
        "source": f"lss rig --set {case.set} --seed {case.seed}" + (
            f" --protocol {case.protocol.name}" if case.protocol.name != "steady" else "") + (
            f" --repeat {case.repeat}" if case.repeat else ""),
        "notes": (f"Synthetic measurement {case.number} of the paper's campaign: layout {case.layout[-1]}, "
                  f"speed set point {case.speed_nominal:g} m/s, pretension {case.pretension_factor:g} x the "
                  f"layout's nominal. " + _logging_note(case, n_samples, full_lap)),
        "sensor": sensor.describe(),
    }
    if case.protocol.name != "steady":   # a steady record reads as before: steady is the default
        meta["protocol"] = case.protocol.to_meta()
    meta["design_variables"] = design.bounds_from_meta(meta)
    return meta


def _logging_note(case: Case, n_samples: int, full_lap: bool) -> str:
    p = case.protocol
    if p.name == "start-stop":
        return (f"Start-stop from standstill, the transducer cart parked at the trigger point; the set point "
                f"steps to {case.speed_nominal:g} m/s at the start command, which starts logging, and back to 0 "
                f"{p.step_time:g} s later (the drive brakes; {n_samples} samples).")
    if p.from_rest:
        return (f"Start-up from standstill, the transducer cart parked at the trigger point; the set point "
                f"steps to {case.speed_nominal:g} m/s at the start command, which starts logging "
                f"({n_samples} samples).")
    if p.name == "speed-step":
        return (f"Running at {p.v_from:g} m/s; logging from the photocell at the trigger point; the set point "
                f"steps to {case.speed_nominal:g} m/s {p.step_time:g} s later ({n_samples} samples).")
    if p.name == "stop":
        return (f"Logging from the photocell at the trigger point; the set point drops to 0 {p.step_time:g} s "
                f"later (a stop under drive braking; {n_samples} samples).")
    return ("Logging from the photocell at the trigger point "
            + ("for one lap." if full_lap else f"for {n_samples} samples (shortened run, not a full lap)."))


def truth_for(case: Case, acq: dict, sensor: SensorModel, gen: dict, fmu_sha: str) -> dict:
    return {
        "WARNING": "ground truth: identification must never read this file",
        "set": case.set, "number": case.number, "id": case.id, "seed": case.seed, "repeat": case.repeat,
        "layout": case.layout,
        "contact_law": case.contact_law, "contact_model": CONTACT_MODELS[case.contact_law],
        "contact_law_note": ("LW, the law identification is expected to recover" if case.contact_law == "LW" else
                             "GZ: the exact Gonthier / Zhang-Sharf relation between CoR and hysteresis "
                             "damping, none of the candidate laws HC, HW, LW, LN"),
        "cor": case.cor,
        "design_variables": case.truth,
        "design_order": list(COR_NAMES) + list(design.META_KEYS),
        "x": [case.cor[k] for k in COR_NAMES] + [case.truth[k] for k in design.META_KEYS],
        "field_deviations": case.field,
        "fmu_parameters": case.fmu_params,
        "layout_fmu": case.layout_fmu if case.layout_fmu == case.layout else case.field.get("as_built_file"),
        "transducer_index": case.transducer,
        "effect_seed": case.effect_seed,
        "effects": case.effects,
        "artefacts": {k: {**v, "applied": acq.get("artefacts", {}).get(k)} for k, v in case.artefacts.items()},
        "settle_time": SETTLE_TIME,
        "protocol": case.protocol.to_meta(),
        "trigger_time_sim": acq["trigger_time"],
        "stop_time_sim": acq["stop_time"],
        "n_samples": acq["n_samples"],
        "full_lap": acq["full_lap"],
        "sensor_offsets_N": acq["offsets_N"],
        "pulse_phase_rad": acq["pulse_phase_rad"],
        "sensor_model": sensor.describe(),
        "fmu_sha256": fmu_sha,
        "generation": gen,
    }


def answers_dir(set_dir: Union[str, Path]) -> Path:
    return Path(set_dir) / "answers"


def load_truth(meas: Union[str, Path, "M.Measurement"]) -> dict:
    """The truth of a synthetic measurement (DIR/answers/mNN/truth.json next to
    the measurement folder DIR/mNN). For evaluating results only."""
    p = Path(meas.path if isinstance(meas, M.Measurement) else meas)
    f = p.parent / "answers" / p.name / "truth.json"
    if not f.is_file():
        raise FileNotFoundError(f"no answer file {f} for {p}")
    return json.loads(f.read_text())


def true_design_values(truth: Mapping) -> dict:
    """The paper's ten design variables of an answer file (load_truth), by
    their FMU names: the CoRs and the layout-dependent values the rig drew."""
    from .design import DESIGN, SYMBOL
    return {**{f"contact.{k}": float(v) for k, v in truth["cor"].items()},
            **{d: float(truth["design_variables"][SYMBOL[d]]) for d in DESIGN[4:]}}


def sha256(path: Union[str, Path]) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


# ---------------------------------------------------------------------------------------
# running one measurement

def simulate_case(case: Case, sim, sensor: SensorModel, lap_seconds: Optional[float] = None,
                  tolerance: Optional[float] = None):
    """Run the FMU for a case and pass the record through the sensor model.
    Returns (samples, acquisition info, record)."""
    outputs = CHANNELS + [S_CHANNEL, "chain.v_mean"]
    proto = case.protocol
    speed = proto.schedule(case.truth["v_s"], case.speed_nominal)
    if proto.transient and tolerance is None:
        tolerance = TRANSIENT_TOLERANCE
    if proto.from_rest:
        rec = sim.simulate(case.stop_time, step=sensor.internal_step, params=case.fmu_params, outputs=outputs,
                           tolerance=tolerance, inputs={"drive.v_ref": speed})
        rec = _with_standstill(rec, REST_LEAD, sensor.internal_step)
        arm, trigger = 0.0, 0.0
    elif proto.transient:
        rec = _simulate_trigger_schedule(sim, case, sensor.internal_step, outputs, tolerance, speed)
        arm, trigger = proto.run_in, None
    else:
        rec = sim.simulate(case.stop_time, step=sensor.internal_step, params=case.fmu_params,
                           outputs=outputs, tolerance=tolerance)
        arm, trigger = SETTLE_TIME, None
    arts = {}
    if case.artefacts:  # outside the catalogue: in the sensor stage, before the anti-alias filter
        rec, arts = E.apply_artefacts(rec, case.artefacts, case.track_length, arm_time=arm)
    rng = np.random.default_rng([case.seed, case.number, 1] + ([case.repeat] if case.repeat else []))
    n = None if lap_seconds is None and not proto.transient else int(round(
        (TRANSIENT_RECORD if lap_seconds is None else lap_seconds) * sensor.sample_rate))
    samples, acq = sensor.acquire(rec, case.truth["s_M"], case.track_length, rng, arm_time=arm,
                                  n_samples=n, trigger_time=trigger)
    for info in arts.values():
        info["centres_since_trigger_s"] = [tc - acq["trigger_time"] for tc in info["centres_sim_s"]]
    acq["artefacts"] = arts
    if proto.transient:   # the whole record the protocol defines ('full_lap': complete, not shortened)
        acq["full_lap"] = lap_seconds is None
    return samples, acq, rec


def _with_standstill(rec, lead: float, h: float):
    """The record with `lead` s of standstill before t = 0 (the values at t = 0):
    what the logger's filter and wheel counters saw before the start command."""
    import pandas as pd
    k = int(round(lead / h))
    head = pd.DataFrame(np.repeat(rec.iloc[:1].to_numpy(), k, axis=0), columns=rec.columns)
    head["time"] = -h * np.arange(k, 0, -1)
    return pd.concat([head, rec], ignore_index=True)


def _simulate_trigger_schedule(sim, case: Case, h: float, outputs: list, tolerance, speed):
    """The record of a speed step or a stop: the set point follows `speed` from
    the photocell's trigger (the first forward crossing of s_M after the run-in,
    the rule of sensor.trigger_times) on, so the crossing is found as the run goes."""
    import pandas as pd

    from .triggered import crossing_fraction
    s_M, L, arm = case.truth["s_M"] % case.track_length, case.track_length, case.protocol.run_in
    v_before = float(case.fmu_params["drive.v_ref"])
    t_on = None
    inputs = {"drive.v_ref": lambda t: v_before if t_on is None else speed(t - t_on)}
    j = outputs.index(S_CHANNEL)
    rows, times = [], []
    for t, val in sim.stream(h, outputs, case.fmu_params, tolerance, inputs=inputs):
        if t_on is None and times and t > arm:
            frac = crossing_fraction(rows[-1][j], float(val[j]), s_M, L)
            if frac is not None and times[-1] + frac * (t - times[-1]) >= arm:
                t_on = times[-1] + frac * (t - times[-1])
        rows.append(val.copy())
        times.append(t)
        if t >= case.stop_time:
            break
    df = pd.DataFrame(np.asarray(rows), columns=outputs)
    df.insert(0, "time", np.asarray(times))
    return df


def run_measurement(set_name: str, number: int, out: Union[str, Path], sim, seed: int = DEFAULT_SEED,
                    lap_seconds: Optional[float] = None, sensor: Optional[SensorModel] = None,
                    fmu_sha: str = "", overwrite: bool = False, extra_params: Optional[Mapping] = None,
                    effects: Sequence[str] = (), effect_seed: Optional[int] = None,
                    artefacts: Sequence[str] = (), protocol: str = "steady", repeat: int = 0,
                    effect_values: Optional[Mapping[str, float]] = None) -> dict:
    """Simulate one measurement and write DIR/mNN and DIR/answers/mNN/truth.json
    (`repeat`, `effect_values`: make_case's)."""
    out = Path(out)
    sensor = sensor or SensorModel()
    t0, c0 = time.perf_counter(), time.process_time()
    case = make_case(set_name, number, seed, answers_dir(out), lap_seconds, extra_params, effects, effect_seed,
                     artefacts, protocol, repeat, effect_values)
    samples, acq, _ = simulate_case(case, sim, sensor, lap_seconds)
    t_sim_wall, t_sim_cpu = time.perf_counter() - t0, time.process_time() - c0
    meta = meta_for(case, sensor, acq["n_samples"], acq["full_lap"])
    folder = out / folder_name(number)
    if folder.exists() and overwrite:
        shutil.rmtree(folder)
    M.write_measurement(folder, samples, meta, overwrite=overwrite,
                        comments=[f"{case.id}: virtual transducer cart, layout {case.layout}, "
                                  f"{case.speed_nominal:g} m/s, written by lss_fmu.rig"])
    gen = {"wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
           "simulation_wall_s": t_sim_wall, "simulation_cpu_s": t_sim_cpu,
           "simulated_time_s": case.stop_time, "n_carts": case.n_carts,
           "cart_seconds_per_cpu_second": case.n_carts * case.stop_time / max(t_sim_cpu, 1e-9),
           "host": os.uname().nodename, "finished": _dt.datetime.now().isoformat(timespec="seconds")}
    truth = truth_for(case, acq, sensor, gen, fmu_sha)
    adir = answers_dir(out) / folder_name(number)
    adir.mkdir(parents=True, exist_ok=True)
    (adir / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    if case.field:
        write_field_survey(out, number, case)
    return {"number": number, "layout": case.layout, "id": case.id, "n_samples": acq["n_samples"],
            "full_lap": acq["full_lap"], **{k: gen[k] for k in ("wall_s", "cpu_s", "simulated_time_s",
                                                               "cart_seconds_per_cpu_second")}}


def write_field_survey(out: Path, number: int, case: "Case") -> Path:
    """What a survey of a field-set sorter gives (lss_fmu.survey): its
    as-built track (a copy beside the survey), the carts' mass factor and the
    guide gap the rig drew, as DIR/survey/mNN.json."""
    sdir = out / survey.FOLDER
    track = None
    if case.field.get("as_built_file"):
        src = out / case.field["as_built_file"]
        track = sdir / "tracks" / src.name
        track.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(track, src.read_text())
    return survey.write_survey(sdir / f"{folder_name(number)}.json", case.field, track)


# ---------------------------------------------------------------------------------------
# a whole set, in parallel

_WORKER = {}


def _init_worker(fmu: str) -> None:
    from .runner import ChainSimulator
    _WORKER["sim"] = ChainSimulator(Path(fmu), instance_name=f"rig{os.getpid()}")


def _work(set_name, number, out, seed, lap_seconds, fmu_sha, overwrite, fx=((), None, (), "steady", 0)):
    try:
        return run_measurement(set_name, number, out, _WORKER["sim"], seed, lap_seconds, fmu_sha=fmu_sha,
                               overwrite=overwrite, effects=fx[0], effect_seed=fx[1], artefacts=fx[2],
                               protocol=fx[3], repeat=fx[4] if len(fx) > 4 else 0)
    except Exception as exc:  # one failed measurement must not stop the set
        return {"number": number, "error": f"{type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc()}


def _existing(out: Path, number: int, set_name: str, seed: int, sha: str,
              fx: tuple = ((), None, (), "steady", 0), lap_seconds: Optional[float] = None) -> Optional[str]:
    """None if measurement `number` is not in `out`; "" if it is there and is what
    this run would make (same set, seed, FMU, parameters, undeclared effects and
    artefacts, protocol, repeat, record length: the full one, or the samples of
    `lap_seconds`); otherwise the reason why it differs. `fx`: (effects,
    effect_seed, artefacts, protocol[, repeat]) of this run."""
    folder, truth = out / folder_name(number), answers_dir(out) / folder_name(number) / "truth.json"
    if not (folder / M.META_FILE).is_file() or not truth.is_file():
        return None
    try:
        t = json.loads(truth.read_text())
    except Exception as exc:
        return f"its answer file cannot be read ({exc})"
    if t.get("set") != set_name or t.get("seed") != seed:
        return f"it is from set '{t.get('set')}', seed {t.get('seed')}"
    if lap_seconds is None and not t.get("full_lap", False):
        return "it is a shortened run (--lap-seconds)"
    if lap_seconds is not None:
        want = int(round(float(lap_seconds) * SensorModel().sample_rate))
        if t.get("full_lap", False) or t.get("n_samples") != want:
            return (f"it is {t.get('n_samples')} samples long{' (full)' if t.get('full_lap') else ''}, not the "
                    f"{want} of --lap-seconds {float(lap_seconds):g}")
    if t.get("fmu_sha256") != sha:
        return f"it was made with another FMU (sha256 {str(t.get('fmu_sha256'))[:12]}...)"
    # with the answers folder: the field set's as-built track (rewritten, the same file) is what the
    # chain's length, and so a from-rest protocol's relax time, came from
    case = make_case(set_name, number, seed, answers_dir(out), effects=fx[0], effect_seed=fx[1], artefacts=fx[2],
                     protocol=fx[3], repeat=fx[4] if len(fx) > 4 else 0)
    if int(t.get("repeat") or 0) != case.repeat:
        return f"it is repeat {int(t.get('repeat') or 0)} of the protocol, not {case.repeat}"
    had_protocol = t.get("protocol") or Protocol("steady", run_in=SETTLE_TIME).to_meta()
    if had_protocol != case.protocol.to_meta():
        return f"it was measured with protocol {had_protocol.get('name')}, not {case.protocol.name}"
    had = (sorted(t.get("effects") or {}), sorted(t.get("artefacts") or {}))
    if had != (sorted(case.effects), sorted(case.artefacts)):
        named = lambda e, a: ", ".join(e + a) or "none"  # noqa: E731
        return (f"it was made with other undeclared effects ({named(*had)}; this run: "
                f"{named(sorted(case.effects), sorted(case.artefacts))})")
    if t.get("effect_seed") != case.effect_seed:
        return f"its undeclared effects were drawn with effect seed {t.get('effect_seed')}, not {case.effect_seed}"
    have_art = {k: {a: b for a, b in v.items() if a != "applied"} for k, v in (t.get("artefacts") or {}).items()}
    if have_art != case.artefacts:
        return "its artefacts differ from what this version of the rig draws"
    want = {k: v for k, v in case.fmu_params.items() if k != "layout.name"}
    have = {k: v for k, v in t.get("fmu_parameters", {}).items() if k != "layout.name"}
    if want != have:
        diff = sorted(k for k in set(want) | set(have) if want.get(k) != have.get(k))
        return f"its parameters differ from what this version of the rig draws ({', '.join(diff)})"
    return ""


def generate_set(set_name: str, out: Union[str, Path], numbers: Optional[Sequence[int]] = None,
                 seed: int = DEFAULT_SEED, workers: Optional[int] = None, fmu: Optional[Union[str, Path]] = None,
                 lap_seconds: Optional[float] = None, overwrite: bool = False, progress: bool = True,
                 log=print, effects: Sequence[str] = (), effect_seed: Optional[int] = None,
                 artefacts: Sequence[str] = (), protocol: str = "steady", repeat: int = 0) -> list:
    """Generate measurements of a set into `out`, in parallel, measured with
    `protocol` (rig_protocol: steady, start-up, speed-step, stop, start-stop).

    Measurements already in `out` that this run would make identically (same
    set, seed, FMU and parameters, full lap) are kept, so an interrupted run
    resumes; with overwrite=True they are made again. A set folder holds one
    FMU: if any measurement in `out` differs (other FMU, seed, parameters or a
    shortened run), the run stops with the reason unless overwrite=True, and
    then every such measurement is made again too. The FMU is copied into
    out/fmu/ first, so a rebuild during the run changes nothing. Returns one
    result dict per measurement (with 'error' for a failed one).

    `effects`, `effect_seed`, `artefacts`: undeclared effects switched on in
    every measurement of the run (make_case); different ones make a different
    measurement."""
    from tqdm import tqdm

    from .runner import fmu_path
    if set_name not in SETS:
        raise ValueError(f"unknown set {set_name!r} (known: {', '.join(SETS)})")
    rig_protocol(protocol, 1.0)   # an unknown name: refused before anything is written
    make_case(set_name, ALL_NUMBERS[0], seed, protocol=protocol, repeat=repeat)   # so is a repeat it cannot make
    effects, artefacts = E.parse_effects(effects), E.parse_artefacts(artefacts)
    fx = (tuple(effects), None if not (effects or artefacts) else int(seed if effect_seed is None else effect_seed),
          tuple(artefacts), protocol, int(repeat))
    numbers = list(ALL_NUMBERS) if numbers is None else sorted(set(int(n) for n in numbers))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    src = fmu_path(None if fmu is None else Path(fmu))
    lacks = E.fmu_lacks(src, effects) if effects else []
    if lacks:
        raise ValueError(f"the FMU {src} has no parameter {', '.join(lacks)}: build an FMU with the effects "
                         f"catalogue (lss build) or leave out --effects {','.join(effects)}")
    sha = sha256(src)
    fdir = out / "fmu"
    fdir.mkdir(exist_ok=True)
    fmu_copy = fdir / f"LSSChain-{sha[:12]}.fmu"
    if not fmu_copy.exists():
        shutil.copy2(src, fmu_copy)
    adir = answers_dir(out)
    adir.mkdir(exist_ok=True)
    (adir / "README.txt").write_text(
        "Ground truth of the synthetic measurements in the parent folder.\n"
        "Identification must never read anything in this folder; it is for evaluating results.\n")
    todo, results = [], []
    stale = {}
    for n in ALL_NUMBERS:
        state = _existing(out, n, set_name, seed, sha, fx, lap_seconds)
        if state:
            stale[n] = state
        if n not in numbers:
            continue
        if state == "" and not overwrite:
            results.append({"number": n, "layout": NUMBERING[n], "skipped": "already generated"})
            continue
        todo.append(n)
    if stale and not overwrite:
        lines = "; ".join(f"{folder_name(n)}: {why}" for n, why in sorted(stale.items()))
        raise FileExistsError(f"{out} holds measurements that this run would not make the same way ({lines}). "
                              f"Use overwrite (--overwrite) to make them again, another folder, or --fmu with "
                              f"the FMU in {fdir} that made them")
    todo = sorted(set(todo) | set(stale))
    # longest first: better balance over the workers
    cases = {n: make_case(set_name, n, seed, None, lap_seconds, effects=fx[0], effect_seed=fx[1], artefacts=fx[2],
                          protocol=fx[3], repeat=fx[4])
             for n in todo}
    todo.sort(key=lambda n: -cases[n].cost)
    workers = max(1, min(workers or os.cpu_count() or 1, len(todo) or 1))
    if todo:
        est = sum(c.cost for c in cases.values())
        log(f"lss rig: {len(todo)} measurement(s) of set '{set_name}' (seed {seed}) into {out}, {workers} "
            f"worker(s); {est / 1e3:.0f}k cart-seconds to simulate")
        if effects or artefacts:
            log(f"lss rig: undeclared effects {', '.join(effects + artefacts)} (effect seed {fx[1]}); meta.json "
                f"says nothing about them, the truth is in {answers_dir(out)}")
    bar = tqdm(total=len(todo), desc=f"rig {set_name}", unit="meas", disable=not progress or not todo,
               dynamic_ncols=True)
    try:
        if workers == 1:
            _init_worker(str(fmu_copy))
            try:
                for n in todo:
                    r = _work(set_name, n, str(out), seed, lap_seconds, sha, overwrite, fx)
                    results.append(r)
                    _report(bar, r, log)
                    _write_set_json(out, set_name, seed, sha, fmu_copy, results)
            finally:
                _WORKER.pop("sim").close()
        else:
            with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker,
                                     initargs=(str(fmu_copy),)) as ex:
                futs = [ex.submit(_work, set_name, n, str(out), seed, lap_seconds, sha, overwrite, fx)
                        for n in todo]
                for f in as_completed(futs):
                    r = f.result()
                    results.append(r)
                    _report(bar, r, log)
                    _write_set_json(out, set_name, seed, sha, fmu_copy, results)
    finally:
        bar.close()
    _write_set_json(out, set_name, seed, sha, fmu_copy, results)
    return sorted(results, key=lambda r: r["number"])


def _report(bar, r, log):
    bar.update(1)
    if "error" in r:
        bar.write(f"measurement {r['number']} failed: {r['error']}")
    else:
        bar.set_postfix_str(f"m{r['number']:02d} {r['layout']} {r['wall_s']:.0f} s")


def _write_set_json(out: Path, set_name, seed, sha, fmu_copy, results) -> None:
    f = out / "set.json"
    with locked(f):   # two runs adding measurements to one set each keep the other's entries
        data = {}
        if f.is_file():
            try:
                data = json.loads(f.read_text())
            except Exception:
                data = {}
        if data.get("set") not in (None, set_name) or data.get("seed") not in (None, seed):
            data = {}
        entries = data.get("measurements", {})
        for r in results:
            if "error" in r or "skipped" in r:
                continue
            entries[folder_name(r["number"])] = {k: r[k] for k in ("number", "layout", "n_samples", "full_lap",
                                                                   "wall_s", "cpu_s", "simulated_time_s",
                                                                   "cart_seconds_per_cpu_second")}
        data.update({"set": set_name, "seed": seed, "fmu": str(fmu_copy.relative_to(out)), "fmu_sha256": sha,
                     "description": ("22 measurements of the paper's campaign from the virtual transducer cart "
                                     "(docs/measurements.md); truth in answers/, never read by identification"),
                     "measurements": dict(sorted(entries.items()))})
        write_json_atomic(f, data)


# ---------------------------------------------------------------------------------------
# calibration of the nominal pretension

def calibrate_pretension(layout: str, d_values: Sequence[float], v: float = 2.0, sim=None,
                         laps: float = 1.0) -> list:
    """Mean axial joint force of the transducer cart on straight track, over
    `laps` laps after the settle time, for each pretension d (noise-free FMU
    output at 300 Hz). Used to choose NOMINAL_PRETENSION."""
    from .runner import ChainSimulator
    tr = load_track(layout)
    kinds = np.array([e.kind for e in tr.spec.elements])
    own = sim is None
    sim = sim or ChainSimulator()
    out = []
    try:
        for d in d_values:
            T = SETTLE_TIME + laps * tr.length / v
            c0 = time.process_time()
            df = sim.simulate(T, params={"layout.name": layout, "chain.pretension": float(d), "drive.v_ref": v},
                              record_from=SETTLE_TIME)
            fx = df["transducer.joint.F_x"].to_numpy()
            st = kinds[tr.element_at(df["transducer.s"].to_numpy())] == STRAIGHT
            out.append({"layout": layout, "d": float(d), "preload": float(sim.get("chain.preload")),
                        "Fx_straight_mean": float(fx[st].mean()), "Fx_p5": float(np.percentile(fx, 5)),
                        "Fx_p95": float(np.percentile(fx, 95)), "cpu_s": time.process_time() - c0})
    finally:
        if own:
            sim.close()
    return out
