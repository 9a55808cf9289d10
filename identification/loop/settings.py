"""The closed loop's settings: the budgets of its stages, in one object with
the defaults that work and an expert's table in the same TOML file as the
identification's (`lss close-loop --settings FILE`).

    [identify]            # the base identification: the front door's settings
    max_evals = 300
    [close_loop]
    max_evals = 200         # the complex's evaluations of each extended identification
    fit_evals = 20          # each top candidate fitted alone (raised to what its complex needs)
    refine_evals = 80       # Levenberg-Marquardt simulations ending each extended identification (0: none)
    base_refine_evals = 60  # the base refined to its own optimum before any test (0: none)
    profile_points = 9      # the base's least-determined variable scanned (0: no profile)
    candidates = 4          # candidate effects taken through the extension and the tests per round

An unknown key, a value of the wrong type or out of range is refused with the
file, the key and the value named.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Union

from ..pipeline.base_polish import BASE_REFINE_EVALS, PROFILE_POINTS
from ..pipeline.settings import SettingsError, table_of, typed
from .candidates import REFINE_EVALS, RESCORE_EVALS
from .close_loop import TEST_MAX


@dataclass(frozen=True)
class LoopSettings:
    max_evals: int = 200
    fit_evals: int = RESCORE_EVALS
    refine_evals: int = REFINE_EVALS
    base_refine_evals: int = BASE_REFINE_EVALS
    profile_points: int = PROFILE_POINTS
    candidates: int = TEST_MAX

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def budget(self) -> dict:
        """close_loop's keyword arguments for these settings."""
        return {"max_evals": self.max_evals, "polish_evals": self.max_evals, "fit_evals": self.fit_evals,
                "refine_evals": self.refine_evals, "base_refine_evals": self.base_refine_evals,
                "profile_points": self.profile_points, "test_max": self.candidates}


_AT_LEAST_1 = (int, lambda v: v >= 1, "an integer of at least 1")
_AT_LEAST_0 = (int, lambda v: v >= 0, "an integer of 0 or more")
_RULES = {"max_evals": _AT_LEAST_1, "fit_evals": _AT_LEAST_1, "refine_evals": _AT_LEAST_0,
          "base_refine_evals": _AT_LEAST_0, "profile_points": _AT_LEAST_0, "candidates": _AT_LEAST_1}


def loop_settings_from(mapping: Mapping[str, Any], where: str = "settings") -> LoopSettings:
    """LoopSettings from a mapping of the [close_loop] table's keys."""
    unknown = sorted(set(mapping) - set(_RULES))
    if unknown:
        raise SettingsError(f"{where}: unknown key {unknown[0]!r}: the keys are {', '.join(sorted(_RULES))}")
    return LoopSettings(**{k: typed(_RULES, k, v, where) for k, v in mapping.items()})


def load_loop_settings(path: Union[str, Path, None]) -> LoopSettings:
    """The settings of a TOML file's [close_loop] table (None: the defaults)."""
    if path is None:
        return LoopSettings()
    return loop_settings_from(table_of(path, "close_loop"), where=f"{path} [close_loop]")


__all__ = ["LoopSettings", "load_loop_settings", "loop_settings_from"]
