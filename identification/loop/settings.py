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
    polish_evals = 200      # the complex again from the base at the start of each round (default max_evals; 0: none)
    regrow_evals = 200      # an extension that passes but stays above the noise, identified over growing
                            # windows with this many complex evaluations (default max_evals; 0: not)

`LoopSettings` is the one object the loop's functions take (close_loop, its
rounds and the tests of each candidate); `base_evals` and `first_window` say
how `close_loop` identifies a base it is not given (`lss close-loop` always
gives it the front door's).

An unknown key, a value of the wrong type or out of range is refused with the
file, the key and the value named.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Optional, Union

from ..pipeline.base_polish import BASE_REFINE_EVALS, PROFILE_POINTS
from ..pipeline.growing import FIRST
from ..pipeline.settings import SettingsError, table_of, typed

RESCORE_EVALS = 20   # each top candidate fitted alone through the FMU with this many evaluations
REFINE_EVALS = 80    # simulations of the local refinement (identification.pipeline.refine) ending each extension
TEST_MAX = 4         # candidates taken through the extended identification and the tests, best first: the
                     # linear ranking puts a 2 mm bump or a 3 % heavier cart third or fourth behind periodic
                     # effects; the Bonferroni m counts every hypothesis scanned, so testing more does not
                     # loosen the test (benchmarks/bench_close_loop_rates.py)


@dataclass(frozen=True)
class LoopSettings:
    max_evals: int = 200                   # the complex's evaluations of each extended identification
    fit_evals: int = RESCORE_EVALS         # each top candidate fitted alone
    refine_evals: int = REFINE_EVALS       # Levenberg-Marquardt simulations ending each extension (0: none)
    base_refine_evals: int = BASE_REFINE_EVALS  # the base refined to its own optimum before any test (0: none)
    profile_points: int = PROFILE_POINTS   # the base's least-determined variable scanned (0: no profile)
    candidates: int = TEST_MAX             # candidate effects through the extension and the tests per round
    polish_evals: Optional[int] = None     # the complex from the base at each round's start (None: max_evals)
    regrow_evals: Optional[int] = None     # see the module docstring (None: max_evals with growing windows)
    base_evals: int = 300                  # a base not given: the complex's evaluations (whole-record units)
    first_window: Optional[float] = FIRST  # ... on growing windows from this many seconds (None or 0: whole record)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @property
    def polish(self) -> int:
        return self.max_evals if self.polish_evals is None else self.polish_evals

    @property
    def regrow(self) -> int:
        if self.regrow_evals is not None:
            return self.regrow_evals
        return self.max_evals if self.first_window else 0


_AT_LEAST_1 = (int, lambda v: v >= 1, "an integer of at least 1")
_AT_LEAST_0 = (int, lambda v: v >= 0, "an integer of 0 or more")
_RULES = {"max_evals": _AT_LEAST_1, "fit_evals": _AT_LEAST_1, "refine_evals": _AT_LEAST_0,
          "base_refine_evals": _AT_LEAST_0, "profile_points": _AT_LEAST_0, "candidates": _AT_LEAST_1,
          "polish_evals": _AT_LEAST_0, "regrow_evals": _AT_LEAST_0}


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


__all__ = ["LoopSettings", "REFINE_EVALS", "RESCORE_EVALS", "TEST_MAX", "load_loop_settings", "loop_settings_from"]
