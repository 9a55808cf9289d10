"""The identification's settings: one object with the defaults that work, an
expert's TOML file to change them, and the record of what a run used.

    [identify]
    window = 2.5          # s of a transient record fitted (the whole record if shorter)
    max_evals = 300       # the complex's evaluations on the first window
    refine_evals = 400    # Levenberg-Marquardt simulations after growing (0: none)
    restarts = 1          # whole runs again with the next seed while a record stays off the noise
    start = "auto"        # several records: "complex", "single" or "auto"
    shrink = true         # shorter windows while a CoR is rough or the fit above the noise
    tare = true           # zero errors within 3 sigma of the declared offset taken out
    first_window = 0.3    # s: the complex's window
    hold_rest = true      # the pretension and trigger points fitted first, then held by the complex
    sensitivities = false # Levenberg-Marquardt's Jacobians from the FMU's forward sensitivities (records from rest)
    steady_evals = 600    # a steady record: the complex's evaluations on the statistics objective
    free = ["e_JA", "e_JR", "e_SW", "e_RW", "v_s", "d", "mu_d", "s_M", "K_P", "K_I"]

The defaults are the pipeline of the recovery table (docs/identification.md).
An unknown key, a value of the wrong type or out of range is refused with the
file, the key and the value named; nothing runs on a guess.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Optional, Union

from lss_fmu.design import DESIGN, parse_free, symbol

STARTS = ("complex", "single", "auto")


class SettingsError(ValueError):
    """A settings file or mapping that cannot be used; names the source, the key and the value."""


@dataclass(frozen=True)
class Settings:
    window: float = 2.5
    max_evals: int = 300
    refine_evals: int = 400
    restarts: int = 1
    start: str = "auto"
    shrink: bool = True
    tare: bool = True
    first_window: float = 0.3
    hold_rest: bool = True
    sensitivities: bool = False
    steady_evals: int = 600
    free: tuple = field(default=DESIGN)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["free"] = [symbol(n) for n in self.free]
        return d


# key -> (type check, condition, what it must be)
_RULES = {
    "window": (float, lambda v: math.isfinite(v) and v > 0, "a positive number of seconds"),
    "max_evals": (int, lambda v: v >= 1, "an integer of at least 1"),
    "refine_evals": (int, lambda v: v >= 0, "an integer of 0 or more"),
    "restarts": (int, lambda v: 0 <= v <= 10, "an integer from 0 to 10"),
    "start": (str, lambda v: v in STARTS, "one of " + ", ".join(STARTS)),
    "shrink": (bool, lambda v: True, "true or false"),
    "tare": (bool, lambda v: True, "true or false"),
    "first_window": (float, lambda v: math.isfinite(v) and 0 < v <= 2.0, "a number of seconds in (0, 2]"),
    "hold_rest": (bool, lambda v: True, "true or false"),
    "sensitivities": (bool, lambda v: True, "true or false"),
    "steady_evals": (int, lambda v: v >= 1, "an integer of at least 1"),
}


def typed(rules: Mapping[str, tuple], key: str, value: Any, where: str):
    """`value` of `key` checked against `rules` (key -> (type, condition, what
    it must be)); a SettingsError naming `where`, the key and the value."""
    kind, ok, must = rules[key]
    if kind is bool:
        good = isinstance(value, bool)
    elif kind is int:
        good = isinstance(value, int) and not isinstance(value, bool)
    elif kind is float:
        good = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if good else value
    else:
        good = isinstance(value, str)
    if not good or not ok(value):
        raise SettingsError(f"{where}: {key} = {value!r}: must be {must}")
    return value


def settings_from(mapping: Mapping[str, Any], where: str = "settings",
                  base: Optional[Settings] = None) -> Settings:
    """Settings from a mapping of the [identify] table's keys, on top of `base` (default: the defaults)."""
    base = base or Settings()
    known = set(_RULES) | {"free"}
    unknown = sorted(set(mapping) - known)
    if unknown:
        raise SettingsError(f"{where}: unknown key {unknown[0]!r}: the keys are {', '.join(sorted(known))}")
    values = {}
    for key, value in mapping.items():
        if key == "free":
            if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
                raise SettingsError(f"{where}: free = {value!r}: must be a list of design variable names")
            try:
                values["free"] = parse_free(",".join(value))
            except ValueError as exc:
                raise SettingsError(f"{where}: free: {exc}") from None
        else:
            values[key] = typed(_RULES, key, value, where)
    return dataclasses.replace(base, **values)


def read_toml(path: Path, error: type = ValueError) -> dict:
    """A TOML file's tables; an unreadable or malformed file raises `error` naming it."""
    try:
        return tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not TOML: {exc}") from None


TABLES = ("identify", "close_loop")   # a settings file's tables: this one's, identification.loop.settings'


def table_of(path: Union[str, Path], name: str) -> dict:
    """Table [name] of a settings file (empty if absent); a file with a table
    other than TABLES, or [name] not a table, is refused naming the file."""
    path = Path(path)
    data = read_toml(path, SettingsError)
    extra = sorted(set(data) - set(TABLES))
    if extra:
        raise SettingsError(f"{path}: unknown table [{extra[0]}]: the settings live in "
                            + " and ".join(f"[{t}]" for t in TABLES))
    table = data.get(name, {})
    if not isinstance(table, dict):
        raise SettingsError(f"{path}: {name} must be a table")
    return table


def load_settings(path: Union[str, Path, None]) -> Settings:
    """The settings of a TOML file's [identify] table (None: the defaults)."""
    if path is None:
        return Settings()
    return settings_from(table_of(path, "identify"), where=f"{path} [identify]")
