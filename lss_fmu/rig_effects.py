"""Undeclared effects for the virtual transducer cart (issue 7; docs/measurements.md,
"Undeclared effects").

The FMU has a catalogue of model extensions, all off by default
(/tmp/spec/effects_contract.md; the `effects.*` parameters of
lss_fmu/variables.py). The rig can switch some of them on in a synthetic
measurement without saying so in meta.json, so the close-loop analysis can
be tested on data whose metadata declares nothing. This module draws their
parameters from a seed, within ranges chosen to be *detectable* in one
lap of transducer-cart forces yet physically plausible for a sorter that
still runs (the module constants below; the reasons are in the docs).

It also makes artefacts that are NOT in the catalogue, for testing that
the analysis says "nothing in my catalogue explains this" (issues 7 and 18):

* `channel_bump`, a smooth pulse on one force channel each time the
  transducer cart passes one place (a loose cable, a bolt hitting a bracket);
* `interference`, a sinusoid on one force channel at a frequency in Hz that
  no wheel, cart or motor order of the catalogue reaches (INTERFERENCE_HZ:
  above the thrust ripple's v / pitch and the wheel orders at the rig's
  speeds), e.g. a converter's pick-up on an amplifier;
* `clock_drift`, the logger's clock running fast by a relative eps: sample k
  is taken at true time t_on + k / (f_s (1 + eps)) but labelled k / f_s;
* `crosstalk`, one force channel leaking into another: y_j + c F_k.

They are applied to the FMU record before the sensor model (lss_fmu.sensor),
so they pass the anti-alias filter like a real force would (the clock
resamples the whole record, the trigger channel included).

    params = draw_effects(["wheel_oor", "sensor"], seed=7, layout="layout7")
    truth = effects_truth(["wheel_oor", "sensor"], 7, "layout7")   # with the details
    art = draw_artefacts(["channel_bump"], 7, track_length=65.0)
    record2, info = apply_artefacts(record, art, track_length=65.0, arm_time=4.0)

Every draw comes from numpy.random.default_rng([seed, stream, k]) with k the
effect's place in CATALOGUE, so an effect's draw does not depend on which other
effects are requested; the rig passes the layout's number as `stream`, so
each sorter (layout) gets its own effects and every measurement on it the same.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable, Mapping, Optional, Sequence, Union

import numpy as np
import pandas as pd

from .layout_format import KIND_NAMES
from .sensor import OFFSET_STD
from .variables import BY_NAME, FORCE_CHANNELS

CATALOGUE = ("wheel_oor", "track_bump", "joint_clearance", "motor_ripple", "resistance", "sensor", "mass")
ARTEFACT = "channel_bump"
ARTEFACTS = (ARTEFACT, "interference", "clock_drift", "crosstalk")

DESCRIPTIONS = {
    "wheel_oor": "out-of-round driving wheels on the transducer cart (radial runout, k lobes)",
    "track_bump": "a cosine bump or dip of the running surface at an element joint",
    "joint_clearance": "play in every cart-to-cart joint (dead band before contact)",
    "motor_ripple": "thrust ripple (cogging) of every linear motor",
    "resistance": "velocity-dependent running resistance per cart, F = -c1 v",
    "sensor": "gain and offset errors of 1-3 transducer force channels",
    "mass": "heavier transducer cart (instrumentation) and a spread of the other carts' masses",
    ARTEFACT: "a smooth pulse on ONE force channel when the transducer cart passes one place (a loose "
              "cable, a bolt hitting a bracket); added before the sensor model, not in the catalogue",
    "interference": "a sinusoid on ONE force channel at a frequency (Hz) unrelated to the wheel, cart and "
                    "motor orders (electrical pick-up); added before the sensor model, not in the catalogue",
    "clock_drift": "the logger's clock running slightly fast: the record is time-stretched by 1 + eps; not "
                   "in the catalogue",
    "crosstalk": "one force channel leaking into another (y_j + c F_k); not in the catalogue",
}

# --- the draw ranges (uniform unless said); docs/measurements.md gives the reasons --------------
# wheel_oor: on the transducer cart's two driving wheels (cart -1), so its forces see it directly
# with k lobes the runout is this range / k^2, so the radial acceleration a (k w)^2 that loads the
# contact has the same range for every k (1 mm with k = 2 would lift the wheel off at 3 m/s)
WHEEL_OOR_AMPLITUDE = (0.3e-3, 1.0e-3)     # m, radial runout a of an eccentric wheel (k = 1)
WHEEL_OOR_ORDERS = (1, 2)                  # k, drawn from these (1 = eccentric, 2 = oval)
WHEEL_OOR_CART = -1                        # -1 = the transducer cart
# track_bump: at a randomly chosen element joint of the layout, either sign
TRACK_BUMP_HEIGHT = (1.0e-3, 3.0e-3)       # m, |H|; the sign is drawn (bump or dip)
TRACK_BUMP_LENGTH = (0.1, 0.3)             # m
# joint_clearance: the same gap in every joint, as a fraction of the stretch per joint d_nom / N that
# the layout's nominal pretension gives (0.1 mm on layout 3 to 0.44 mm on layout 7): a gap larger than
# the stretch leaves the chain without preload (on layout 1 at 0.5 mm the joint is slack 87 % of a lap)
JOINT_CLEARANCE_REL = (0.05, 0.3)
# motor_ripple
MOTOR_RIPPLE_AMPLITUDE = (50.0, 200.0)     # N
MOTOR_RIPPLE_PITCH = (0.05, 0.2)           # m
# resistance: per cart, linear in speed (c2, the quadratic term, stays 0). At 3 m/s, c1 = 5 adds 15 N
# per cart to the 6.6 N of rolling resistance: the motors of layout 1 (13 carts per motor) then need 300
# of their 400 N; c1 = 20 saturates them and the chain slows (layout 7: 2.4 m/s instead of 3.0)
RESISTANCE_C1 = (2.0, 5.0)                 # N.s/m
# sensor: on 1-3 of the 7 force channels, each gets a gain error and an offset, random signs. A fault,
# not a tolerance: the offset stands clear of the specification (the floor) by 6-15 % of the working
# level; at 2 % it was lost in the noise on channels that swing 1000 N (steering wheels on layout 7)
SENSOR_N_CHANNELS = (1, 3)
SENSOR_GAIN = (0.03, 0.10)                 # |g|, relative
SENSOR_OFFSET_REL = (0.06, 0.15)           # |o| above the floor, as a fraction of SENSOR_LEVEL_N
SENSOR_OFFSET_FLOOR_SIGMAS = 3.0           # floor of |o|: this many taring-offset std (sensor.OFFSET_STD)
SENSOR_LEVEL_N = {                         # typical working level of each channel over a lap, N
    "transducer.joint.F_x": 1000.0,        # joint tension, about 900 N on straights by calibration
    "transducer.joint.F_y": 300.0,
    "transducer.joint.F_z": 300.0,
    "transducer.steering.F_left": 300.0,
    "transducer.steering.F_right": 300.0,
    "transducer.driving.F_left": 250.0,    # the cart's weight on one driving wheel, ~200 N
    "transducer.driving.F_right": 250.0,
}
# mass
MASS_TRANSDUCER_FACTOR = (1.15, 1.5)
MASS_SPREAD = (0.0, 0.05)
MASS_SEED_MAX = 2 ** 31 - 1                # FMI Integer is 32 bit
# channel_bump (artefact)
ARTEFACT_DURATION = (0.1, 0.3)             # s, raised-cosine pulse, full width
ARTEFACT_REL_AMPLITUDE = (0.05, 0.15)      # of the channel's range (1st to 99th percentile after arming)
ARTEFACT_RANGE_FLOOR_N = 150.0             # the range used is at least this (quiet channels)
ARTEFACT_MARGIN_M = 2.0                    # m kept clear of the trigger point on each side
# interference: above the thrust ripple's band (v / pitch <= 3 m/s / 0.05 m = 60 Hz) and the orders of an
# out-of-round wheel (k <= 6 lobes and harmonics: 6 v / (2 pi 0.05 m) = 57 Hz at 3 m/s), below the
# logger's anti-alias cutoff (100 Hz)
INTERFERENCE_HZ = (62.0, 92.0)
INTERFERENCE_REL_AMPLITUDE = (0.01, 0.04)  # of the channel's range (as ARTEFACT_RANGE_FLOOR_N)
CLOCK_DRIFT = (1.0e-3, 4.0e-3)             # relative: the logger's clock this much fast
CROSSTALK_FACTOR = (0.02, 0.06)            # of the source channel's force, either sign

# The FMU parameters each effect may set (the sensor effect sets those of its drawn channels only)
_CH = [c.removeprefix("transducer.") for c in FORCE_CHANNELS]
PARAMETERS = {
    "wheel_oor": ("effects.wheel_oor.amplitude", "effects.wheel_oor.order", "effects.wheel_oor.phase_left",
                  "effects.wheel_oor.phase_right", "effects.wheel_oor.cart"),
    "track_bump": ("effects.track_bump.height", "effects.track_bump.s", "effects.track_bump.length"),
    "joint_clearance": ("effects.joint_clearance.gap",),
    "motor_ripple": ("effects.motor_ripple.amplitude", "effects.motor_ripple.pitch",
                     "effects.motor_ripple.phase"),
    "resistance": ("effects.resistance.c1",),
    "sensor": tuple(f"effects.sensor.{kind}.{c}" for c in _CH for kind in ("gain", "offset")),
    "mass": ("effects.mass.transducer_factor", "effects.mass.spread", "effects.mass.seed"),
}

# The documented range of each drawn quantity, for the docs and the tests:
# parameter -> (lo, hi) of its value (or of its absolute value, see ABS_RANGE)
# (wheel_oor.amplitude depends on the order, joint_clearance.gap on the layout: see _draw_one)
RANGES = {
    "effects.wheel_oor.amplitude": (WHEEL_OOR_AMPLITUDE[0] / max(WHEEL_OOR_ORDERS) ** 2, WHEEL_OOR_AMPLITUDE[1]),
    "effects.wheel_oor.order": (min(WHEEL_OOR_ORDERS), max(WHEEL_OOR_ORDERS)),
    "effects.wheel_oor.phase_left": (0.0, 2 * math.pi),
    "effects.wheel_oor.phase_right": (0.0, 2 * math.pi),
    "effects.wheel_oor.cart": (WHEEL_OOR_CART, WHEEL_OOR_CART),
    "effects.track_bump.height": TRACK_BUMP_HEIGHT,
    "effects.track_bump.length": TRACK_BUMP_LENGTH,
    "effects.motor_ripple.amplitude": MOTOR_RIPPLE_AMPLITUDE,
    "effects.motor_ripple.pitch": MOTOR_RIPPLE_PITCH,
    "effects.motor_ripple.phase": (0.0, 2 * math.pi),
    "effects.resistance.c1": RESISTANCE_C1,
    **{f"effects.sensor.gain.{c}": SENSOR_GAIN for c in _CH},
    **{f"effects.sensor.offset.{c.removeprefix('transducer.')}":
       tuple(SENSOR_OFFSET_FLOOR_SIGMAS * OFFSET_STD[c] + r * SENSOR_LEVEL_N[c] for r in SENSOR_OFFSET_REL)
       for c in FORCE_CHANNELS},
    "effects.mass.transducer_factor": MASS_TRANSDUCER_FACTOR,
    "effects.mass.spread": MASS_SPREAD,
    "effects.mass.seed": (0, MASS_SEED_MAX),
}
# drawn with either sign: the range is that of the absolute value
ABS_RANGE = {"effects.track_bump.height"} | {f"effects.sensor.{k}.{c}" for c in _CH for k in ("gain", "offset")}


# ---------------------------------------------------------------------------------------------
# names

def _split(names: Union[str, Iterable[str], None]) -> list:
    if names is None:
        return []
    if isinstance(names, str):
        names = names.split(",")
    return [n.strip() for n in names if n and n.strip()]


def parse_effects(names: Union[str, Iterable[str], None], option: str = "effects") -> list:
    """'wheel_oor, sensor' or a list -> the names in catalogue order, each once;
    'all' -> the whole catalogue. ValueError naming the known effects for an unknown one."""
    got = _split(names)
    if [n.lower() for n in got] == ["all"]:
        return list(CATALOGUE)
    bad = [n for n in got if n not in CATALOGUE]
    if bad:
        hint = (f"; '{ARTEFACT}' is an artefact outside the catalogue: use --artefact"
                if ARTEFACT in bad else "")
        raise ValueError(f"{option}: unknown effect{'s' if len(bad) > 1 else ''} {', '.join(map(repr, bad))} "
                         f"(known: {', '.join(CATALOGUE)}, or all){hint}")
    return [n for n in CATALOGUE if n in got]


def parse_artefacts(names: Union[str, Iterable[str], None], option: str = "artefact") -> list:
    """Like parse_effects for the artefacts outside the catalogue (ARTEFACTS)."""
    got = _split(names)
    bad = [n for n in got if n not in ARTEFACTS]
    if bad:
        hint = "; catalogue effects go to --effects" if any(n in CATALOGUE for n in bad) else ""
        raise ValueError(f"{option}: unknown artefact{'s' if len(bad) > 1 else ''} {', '.join(map(repr, bad))} "
                         f"(known: {', '.join(ARTEFACTS)}){hint}")
    return [n for n in ARTEFACTS if n in got]


# ---------------------------------------------------------------------------------------------
# the draws

def _track(layout):
    from .layouts import load_track
    from .track_geometry import Track
    if isinstance(layout, Track):
        return layout
    return load_track(str(layout) if isinstance(layout, Path) else layout)


def _rng(seed: int, stream: int, key: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), int(stream), int(key)])


def _signed(rng, lo, hi) -> float:
    mag = float(rng.uniform(lo, hi))
    return mag if rng.random() < 0.5 else -mag


def _draw_one(name: str, rng: np.random.Generator, track, transducer: Optional[int],
              pretension: Optional[float]) -> dict:
    """One effect: {"parameters": {FMU name: value}, ...details for the truth}."""
    two_pi = 2.0 * math.pi
    if name == "wheel_oor":
        a1 = float(rng.uniform(*WHEEL_OOR_AMPLITUDE))
        k = int(rng.choice(WHEEL_OOR_ORDERS))
        p = {"effects.wheel_oor.amplitude": a1 / k ** 2,
             "effects.wheel_oor.order": k,
             "effects.wheel_oor.phase_left": float(rng.uniform(0.0, two_pi)),
             "effects.wheel_oor.phase_right": float(rng.uniform(0.0, two_pi)),
             "effects.wheel_oor.cart": int(WHEEL_OOR_CART)}
        cart = transducer if WHEEL_OOR_CART == -1 else WHEEL_OOR_CART
        return {"parameters": p, "cart_index": None if cart is None else int(cart), "amplitude_times_order2_m": a1}
    if name == "track_bump":
        joints = [float(s) for s in track.s0]
        i = int(rng.integers(len(joints)))
        p = {"effects.track_bump.height": _signed(rng, *TRACK_BUMP_HEIGHT),
             "effects.track_bump.s": joints[i] % float(track.length),
             "effects.track_bump.length": float(rng.uniform(*TRACK_BUMP_LENGTH))}
        kinds = [KIND_NAMES.get(e.kind, str(e.kind)) for e in track.spec.elements]
        return {"parameters": p, "joint_index": i, "between": [kinds[i - 1], kinds[i]]}
    if name == "joint_clearance":
        stretch = float(pretension) / int(track.n_carts)
        f = float(rng.uniform(*JOINT_CLEARANCE_REL))
        return {"parameters": {"effects.joint_clearance.gap": f * stretch},
                "stretch_per_joint_m": stretch, "fraction_of_stretch": f}
    if name == "motor_ripple":
        return {"parameters": {"effects.motor_ripple.amplitude": float(rng.uniform(*MOTOR_RIPPLE_AMPLITUDE)),
                               "effects.motor_ripple.pitch": float(rng.uniform(*MOTOR_RIPPLE_PITCH)),
                               "effects.motor_ripple.phase": float(rng.uniform(0.0, two_pi))}}
    if name == "resistance":
        return {"parameters": {"effects.resistance.c1": float(rng.uniform(*RESISTANCE_C1))}}
    if name == "sensor":
        n = int(rng.integers(SENSOR_N_CHANNELS[0], SENSOR_N_CHANNELS[1] + 1))
        chans = [FORCE_CHANNELS[j] for j in sorted(rng.choice(len(FORCE_CHANNELS), size=n, replace=False))]
        p, detail = {}, {}
        for c in chans:
            short = c.removeprefix("transducer.")
            g = _signed(rng, *SENSOR_GAIN)
            floor = SENSOR_OFFSET_FLOOR_SIGMAS * OFFSET_STD[c]
            o = _signed(rng, floor + SENSOR_OFFSET_REL[0] * SENSOR_LEVEL_N[c],
                        floor + SENSOR_OFFSET_REL[1] * SENSOR_LEVEL_N[c])
            p[f"effects.sensor.gain.{short}"] = g
            p[f"effects.sensor.offset.{short}"] = o
            detail[c] = {"gain": g, "offset_N": o}
        return {"parameters": p, "channels": detail}
    if name == "mass":
        return {"parameters": {"effects.mass.transducer_factor": float(rng.uniform(*MASS_TRANSDUCER_FACTOR)),
                               "effects.mass.spread": float(rng.uniform(*MASS_SPREAD)),
                               "effects.mass.seed": int(rng.integers(0, MASS_SEED_MAX + 1))}}
    raise ValueError(f"unknown effect {name!r} (known: {', '.join(CATALOGUE)})")


def nominal_pretension(track) -> float:
    """The nominal pretension d (m) of a built-in layout (or its as-built track) from lss_fmu.rig."""
    from .layouts import NOMINAL_PRETENSION
    name = str(track.spec.name).removesuffix("-as-built")
    if name not in NOMINAL_PRETENSION:
        raise ValueError(f"joint_clearance: no nominal pretension known for layout {name!r} "
                         f"(known: {', '.join(NOMINAL_PRETENSION)}); pass pretension=")
    return float(NOMINAL_PRETENSION[name])


def effects_truth(names, seed: int, layout, transducer: Optional[int] = None, stream: int = 0,
                  pretension: Optional[float] = None) -> dict:
    """The drawn effects with their details: {name: {"description", "parameters": {FMU name: value}, ...}}.
    `layout`: a layout name, file or lss_fmu.track_geometry.Track (element joints, number of carts);
    `transducer`: the transducer cart's index (recorded with wheel_oor); `stream`: a second seed
    (the rig gives the layout's number); `pretension`: the layout's nominal pretension d, m (scales
    the joint clearance; default from lss_fmu.layouts.NOMINAL_PRETENSION)."""
    names = parse_effects(names, "effects")
    track = _track(layout) if ("track_bump" in names or "joint_clearance" in names) else None
    if "joint_clearance" in names and pretension is None:
        pretension = nominal_pretension(track)
    out = {}
    for name in names:
        d = _draw_one(name, _rng(seed, stream, CATALOGUE.index(name)), track, transducer, pretension)
        out[name] = {"description": DESCRIPTIONS[name], **d}
    return out


def set_values(effects: dict, values: Mapping[str, float]) -> dict:
    """The drawn effects (effects_truth) with some of their FMU values set by
    the caller instead (a benchmark setting an effect's size: the phases,
    places and pitches stay drawn); the truth lists them under "set". A name
    that no drawn effect has is refused."""
    values = dict(values or {})
    owners = {k: name for name, d in effects.items() for k in d["parameters"]}
    unknown = sorted(set(values) - set(owners))
    if unknown:
        raise ValueError(f"effect value {unknown[0]!r}: not a parameter of the drawn effects "
                         f"({', '.join(sorted(owners)) or 'none drawn'})")
    out = {name: {**d, "parameters": dict(d["parameters"])} for name, d in effects.items()}
    for k, v in values.items():
        d = out[owners[k]]
        d["parameters"][k] = type(d["parameters"][k])(v)
        d["set"] = sorted(set(d.get("set", [])) | {k})
    if "wheel_oor" in out and "amplitude_times_order2_m" in out["wheel_oor"]:   # derived from the set values
        w = out["wheel_oor"]["parameters"]
        out["wheel_oor"]["amplitude_times_order2_m"] = w["effects.wheel_oor.amplitude"] * w["effects.wheel_oor.order"] ** 2
    return out


def draw_effects(names, seed: int, layout, transducer: Optional[int] = None, stream: int = 0,
                 pretension: Optional[float] = None) -> dict:
    """The FMU parameters that switch on the named effects, drawn from the seed
    (names exactly as in the effects contract). See effects_truth for the details."""
    params = {}
    for d in effects_truth(names, seed, layout, transducer, stream, pretension).values():
        params.update(d["parameters"])
    return params


def fmu_lacks(fmu: Union[str, Path], names: Iterable[str]) -> list:
    """The parameters of the named effects that the FMU file does not have."""
    from fmpy import read_model_description
    have = {v.name for v in read_model_description(str(fmu)).modelVariables}
    want = [p for n in parse_effects(list(names)) for p in PARAMETERS[n]]
    return [p for p in want if p not in have]


def python_lacks(names: Iterable[str]) -> list:
    """The parameters of the named effects missing from lss_fmu.variables."""
    return [p for n in parse_effects(list(names)) for p in PARAMETERS[n] if p not in BY_NAME]


# ---------------------------------------------------------------------------------------------
# the artefact outside the catalogue

def draw_artefacts(names, seed: int, track_length: float, stream: int = 0,
                   avoid_s: Optional[float] = None) -> dict:
    """{name: definition} of the named artefacts. channel_bump: one force channel,
    the arc position s where it happens (uniform on the track, at least
    ARTEFACT_MARGIN_M from `avoid_s`, the trigger point, so a logged lap holds
    the whole pulse), its duration, relative amplitude and sign. interference:
    the channel, the frequency (INTERFERENCE_HZ), the relative amplitude and
    the phase. clock_drift: eps. crosstalk: the channel it leaks into, the
    one it comes from and the factor."""
    names = parse_artefacts(names)
    L = float(track_length)
    out = {}
    for name in names:
        rng = _rng(seed, stream, 100 + ARTEFACTS.index(name))
        if name != ARTEFACT:
            out[name] = {"description": DESCRIPTIONS[name], **_draw_other(name, rng)}
            continue
        channel = FORCE_CHANNELS[int(rng.integers(len(FORCE_CHANNELS)))]
        u = float(rng.random())
        if avoid_s is None:
            s = u * L
        else:
            m = min(ARTEFACT_MARGIN_M, 0.25 * L)
            s = (float(avoid_s) + m + u * (L - 2 * m)) % L
        out[name] = {"description": DESCRIPTIONS[name], "channel": channel, "s": s,
                     "duration_s": float(rng.uniform(*ARTEFACT_DURATION)),
                     "relative_amplitude": float(rng.uniform(*ARTEFACT_REL_AMPLITUDE)),
                     "sign": 1 if rng.random() < 0.5 else -1}
    return out


def _draw_other(name: str, rng: np.random.Generator) -> dict:
    if name == "interference":
        return {"channel": FORCE_CHANNELS[int(rng.integers(len(FORCE_CHANNELS)))],
                "frequency_hz": float(rng.uniform(*INTERFERENCE_HZ)),
                "relative_amplitude": float(rng.uniform(*INTERFERENCE_REL_AMPLITUDE)),
                "phase": float(rng.uniform(0.0, 2.0 * math.pi))}
    if name == "clock_drift":
        return {"eps": float(rng.uniform(*CLOCK_DRIFT))}
    if name == "crosstalk":
        j, k = (int(i) for i in rng.choice(len(FORCE_CHANNELS), size=2, replace=False))
        return {"into": FORCE_CHANNELS[j], "from": FORCE_CHANNELS[k], "factor": _signed(rng, *CROSSTALK_FACTOR)}
    raise ValueError(f"unknown artefact {name!r} (known: {', '.join(ARTEFACTS)})")


def channel_range(x: np.ndarray) -> float:
    """The range a relative artefact amplitude refers to: 1st to 99th percentile, at least the floor."""
    return max(float(np.percentile(x, 99) - np.percentile(x, 1)), ARTEFACT_RANGE_FLOOR_N)


def interference_signal(t: np.ndarray, artefact: Mapping, amplitude: float) -> np.ndarray:
    return amplitude * np.sin(2.0 * math.pi * float(artefact["frequency_hz"]) * np.asarray(t, float)
                              + float(artefact["phase"]))


def add_to_forces(t: np.ndarray, forces: np.ndarray, artefact_name: str, artefact: Mapping,
                  ranges: Optional[np.ndarray] = None) -> tuple:
    """interference or crosstalk added to an array of the 7 forces (n, 7) at the
    times t (s); `ranges`: each channel's range for a relative amplitude
    (default: from `forces`). Returns (forces, info)."""
    F = np.array(forces, float)
    if artefact_name == "interference":
        j = FORCE_CHANNELS.index(artefact["channel"])
        rng_N = float(ranges[j]) if ranges is not None else channel_range(F[:, j])
        amp = float(artefact["relative_amplitude"]) * rng_N
        F[:, j] += interference_signal(t, artefact, amp)
        return F, {"channel": artefact["channel"], "amplitude_N": amp, "frequency_hz": artefact["frequency_hz"]}
    if artefact_name == "crosstalk":
        j, k = FORCE_CHANNELS.index(artefact["into"]), FORCE_CHANNELS.index(artefact["from"])
        F[:, j] += float(artefact["factor"]) * np.asarray(forces, float)[:, k]
        return F, {"into": artefact["into"], "from": artefact["from"], "factor": artefact["factor"]}
    raise ValueError(f"{artefact_name}: not an additive artefact")


def clock_resample(record: pd.DataFrame, eps: float, anchor: float = 0.0, s_channel: str = "transducer.s",
                   track_length: Optional[float] = None) -> pd.DataFrame:
    """The record as a logger whose clock runs fast by eps sees it: every column
    at record time tau holds the value of true time anchor + (tau - anchor) / (1 + eps)
    (4-point cubics on the uniform grid; the wrapped track position unwrapped first)."""
    from .sensor import interp_cubic
    t = record["time"].to_numpy(dtype=float)
    h = (t[-1] - t[0]) / (len(t) - 1)
    src = anchor + (t - anchor) / (1.0 + float(eps))
    src = np.clip(src, t[1], t[-3])
    out = record.copy()
    cols = [c for c in record.columns if c != "time"]
    Y = record[cols].to_numpy(dtype=float)
    L = track_length
    if s_channel in cols and L:
        i = cols.index(s_channel)
        Y[:, i] = np.unwrap(Y[:, i], period=float(L))
    Z = interp_cubic(t[0], h, Y, src)
    if s_channel in cols and L:
        Z[:, i] = np.mod(Z[:, i], float(L))
    out[cols] = Z
    return out


def passage_times(t: np.ndarray, s: np.ndarray, s_a: float, track_length: float, after: float = 0.0) -> list:
    """Every time the cart passes s_a going forward (s wrapped into [0, L)), after `after`."""
    L = float(track_length)
    u = np.unwrap(np.asarray(s, dtype=float), period=L)
    lap = np.floor((u - s_a) / L)
    idx = np.nonzero(lap[1:] > lap[:-1])[0] + 1
    out = []
    for i in idx:
        target = s_a + lap[i] * L
        frac = (target - u[i - 1]) / (u[i] - u[i - 1])
        tc = float(t[i - 1] + frac * (t[i] - t[i - 1]))
        if tc >= after:
            out.append(tc)
    return out


def channel_bump(t: np.ndarray, centres: Sequence[float], duration: float, amplitude: float) -> np.ndarray:
    """Raised-cosine pulses A (1 + cos(2 pi (t - tc) / T)) / 2 for |t - tc| < T/2."""
    t = np.asarray(t, dtype=float)
    y = np.zeros_like(t)
    for tc in centres:
        x = (t - tc) / duration
        on = np.abs(x) < 0.5
        y[on] += amplitude * 0.5 * (1.0 + np.cos(2.0 * math.pi * x[on]))
    return y


def apply_channel_bump(record: pd.DataFrame, artefact: Mapping, track_length: float,
                       arm_time: float = 0.0, s_channel: str = "transducer.s"):
    """Add the channel_bump pulse to a copy of an FMU record (time, the force
    channels and transducer.s): one pulse per passage of artefact['s'] after
    arm_time, on artefact['channel'] only. The amplitude in N is
    sign x relative_amplitude x the channel's range in the record after
    arm_time (1st to 99th percentile, at least ARTEFACT_RANGE_FLOOR_N).
    Returns (record, info) with the pulse centres and the amplitude."""
    t = record["time"].to_numpy(dtype=float)
    c = artefact["channel"]
    x = record[c].to_numpy(dtype=float)
    sel = t >= arm_time
    y = x[sel] if sel.any() else x
    rng_N = max(float(np.percentile(y, 99) - np.percentile(y, 1)), ARTEFACT_RANGE_FLOOR_N)
    amp = float(artefact["sign"]) * float(artefact["relative_amplitude"]) * rng_N
    centres = passage_times(t, record[s_channel].to_numpy(dtype=float), float(artefact["s"]),
                            track_length, after=arm_time)
    out = record.copy()
    out[c] = x + channel_bump(t, centres, float(artefact["duration_s"]), amp)
    info = {"channel": c, "amplitude_N": amp, "channel_range_N": rng_N, "centres_sim_s": centres}
    return out, info


def apply_artefacts(record: pd.DataFrame, artefacts: Mapping, track_length: float, arm_time: float = 0.0):
    """Apply every artefact of {name: definition}; returns (record, {name: info}).
    Relative amplitudes refer to the record after arm_time; the clock's
    stretch is anchored at arm_time (the trigger comes after it)."""
    infos = {}
    for name, art in artefacts.items():
        if name == ARTEFACT:
            record, infos[name] = apply_channel_bump(record, art, track_length, arm_time)
        elif name in ("interference", "crosstalk"):
            t = record["time"].to_numpy(dtype=float)
            F = record[FORCE_CHANNELS].to_numpy(dtype=float)
            sel = t >= arm_time
            ranges = np.array([channel_range(F[sel if sel.any() else slice(None), j]) for j in range(F.shape[1])])
            F2, infos[name] = add_to_forces(t, F, name, art, ranges)
            record = record.copy()
            record[FORCE_CHANNELS] = F2
        elif name == "clock_drift":
            record = clock_resample(record, float(art["eps"]), arm_time, track_length=track_length)
            infos[name] = {"eps": float(art["eps"]), "anchor_s": float(arm_time)}
        else:
            raise ValueError(f"unknown artefact {name!r} (known: {', '.join(ARTEFACTS)})")
    return record, infos
