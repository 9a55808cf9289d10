"""The paper's design vector (Eq. 13), in one place.

    x = [e_JA, e_JR, e_SW, e_RW, v_s, d, mu_d, s_M, K_P, K_I]

Each design variable has a name (the FMU variable it sets; `trigger.s_M` is
the trigger alignment, not an FMU value), the paper's symbol (also the key
in meta.json's `design_variables`), a unit, and a bound rule: the CoRs lie
within 0.2..0.9 (the paper), the six layout-dependent variables within
bounds derived from the measurement's nominal values (`bounds_from_meta`).
The rig, the measurement reader, the identification problem and the
reports all read them from here.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Optional

from .variables import BY_NAME, CONTACT_MODELS, FORCE_CHANNELS


@dataclass(frozen=True)
class DesignVariable:
    name: str          # FMU variable (or trigger.s_M)
    symbol: str        # the paper's symbol; meta.json's key
    unit: str
    meaning: str


TRIGGER = "trigger.s_M"

VARIABLES = (
    DesignVariable("contact.e_JA", "e_JA", "1", "coefficient of restitution, joint axial"),
    DesignVariable("contact.e_JR", "e_JR", "1", "coefficient of restitution, joint radial"),
    DesignVariable("contact.e_SW", "e_SW", "1", "coefficient of restitution, steering wheel"),
    DesignVariable("contact.e_RW", "e_RW", "1", "coefficient of restitution, driving wheel"),
    DesignVariable("drive.v_ref", "v_s", "m/s", "sorter speed reference"),
    DesignVariable("chain.pretension", "d", "m", "pretension of the chain"),
    DesignVariable("wheel.mu_roll", "mu_d", "1", "rolling resistance of the wheels"),
    DesignVariable(TRIGGER, "s_M", "m", "trigger point of the logging"),
    DesignVariable("drive.Kp", "K_P", "N.s/m", "proportional gain of the speed controller"),
    DesignVariable("drive.Ki", "K_I", "N/m", "integral gain of the speed controller"),
)

DESIGN = tuple(v.name for v in VARIABLES)              # Eq. 13 order
CORS = DESIGN[:4]                                       # the contact CoRs
LAYOUT_DEPENDENT = DESIGN[4:]                           # bounds from each measurement
SYMBOL = {v.name: v.symbol for v in VARIABLES}
BY_SYMBOL = {v.symbol: v.name for v in VARIABLES}
UNIT = {v.name: v.unit for v in VARIABLES}
META_KEYS = tuple(SYMBOL[n] for n in LAYOUT_DEPENDENT)  # meta.json design_variables keys, in order
COR_SYMBOLS = tuple(SYMBOL[n] for n in CORS)
COR_BOUNDS = (0.2, 0.9)                                 # the paper's explicit CoR bounds

# The seven forces of the objective (u = 7), and how figures and tables name them.
CHANNEL_LABELS = dict(zip(FORCE_CHANNELS, ["joint F_x", "joint F_y", "joint F_z", "steering left",
                                           "steering right", "driving left", "driving right"]))
LABELS = [CHANNEL_LABELS[c] for c in FORCE_CHANNELS]

# Nominal values a measurement may leave out: the FMU's defaults.
MU_ROLL_DEFAULT = float(BY_NAME["wheel.mu_roll"].start)
KP_DEFAULT = float(BY_NAME["drive.Kp"].start)
KI_DEFAULT = float(BY_NAME["drive.Ki"].start)


def symbol(name: str) -> str:
    """The paper's symbol of a design variable; effect parameters keep their FMU name;
    NAME@k (the k-th record's own value in a joint identification) is SYMBOL@k."""
    base, at, k = name.partition("@")
    return SYMBOL.get(name, SYMBOL.get(base, base) + at + k if at else name)


def is_effect_parameter(name: str) -> bool:
    """A model extension of the closed loop (an FMU parameter effects.*) added to the design vector."""
    return name.startswith("effects.") and name in BY_NAME and BY_NAME[name].causality == "parameter"


def bounds_from_meta(meta: Mapping) -> dict:
    """Nominal value and bounds of the six layout-dependent variables from the
    nominal values a test engineer writes down (docs/measurements.md):
    v_s +-5 % of the nominal speed, d 0.5-1.5 x the nominal pretension, mu_d
    1/3-2 x the data-sheet value, s_M +-0.5 m around the nominal trigger point,
    K_P and K_I 1/4-4 x their nominal values. Keyed by symbol, as in meta.json."""
    v = float(meta["speed_nominal"])
    d = float(meta["pretension_nominal"])
    mu = float(meta.get("mu_roll_nominal", MU_ROLL_DEFAULT))
    s_m = float(meta["trigger_point"])
    kp = float(meta.get("Kp_nominal", KP_DEFAULT))
    ki = float(meta.get("Ki_nominal", KI_DEFAULT))
    rule = {
        "v_s": (v, 0.95 * v, 1.05 * v),
        "d": (d, 0.5 * d, 1.5 * d),
        "mu_d": (mu, mu / 3.0, 2.0 * mu),
        "s_M": (s_m, s_m - 0.5, s_m + 0.5),
        "K_P": (kp, kp / 4.0, 4.0 * kp),
        "K_I": (ki, ki / 4.0, 4.0 * ki),
    }
    return {k: {"nominal": a, "lower": lo, "upper": hi, "unit": UNIT[BY_SYMBOL[k]]}
            for k, (a, lo, hi) in rule.items()}


def parse_model(name: str) -> str:
    """A contact model code (HC, HW, LW, LN, GZ, FL; any case) or a ValueError naming it."""
    m = str(name).strip().upper()
    if m not in CONTACT_MODELS:
        raise ValueError(f"unknown contact model {name!r}: use one of {', '.join(CONTACT_MODELS)}")
    return m


def parse_free(text: Optional[str]) -> tuple:
    """'e_JA,e_SW' (symbols or FMU names) -> design names in that order; None or '' -> all ten."""
    if not text:
        return DESIGN
    out = []
    for item in str(text).split(","):
        item = item.strip()
        if not item:
            continue
        name = BY_SYMBOL.get(item, item)
        if name not in DESIGN:
            raise ValueError(f"--free {item!r}: not a design variable ({', '.join(SYMBOL.values())})")
        if name in out:
            raise ValueError(f"--free {item!r}: named twice")
        out.append(name)
    if not out:
        raise ValueError(f"--free {text!r}: names no design variable")
    return tuple(out)
