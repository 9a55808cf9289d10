"""Where a joint identification of several records starts (issue 17).

Three start-stops of one sorter share ten design variables and each has its
own trigger point. The complex over all twelve on the records' first 0.3 s
stops above the noise on some measurements where one record alone does not
(on one layout-2 record: 2.2 per sample on the first window with three
records, 1.05 with one; on one layout-7 record: 8.5 against 1.8), and a
trail that starts off the truth's valley drifts further as the windows grow
(on one layout-6 record: 1.2 per sample on the first window, 30 at 0.9 s;
with one record 1.0 to 0.9 s).

`single_start` starts instead from the first record alone, identified over
its growing windows (growing.grow: the complex on its first window, two
variables fewer to search), taken at the longest window where it is still
at the noise, and puts each further record's trigger point
where that record's first window fits best with the shared values held
(`trigger_scan`: a grid over the trigger's bounds, then a finer one around
its best). Nothing of the truth is used.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional

import numpy as np

from lss_fmu.design import TRIGGER
from lss_fmu.variables import FORCE_CHANNELS

from ..objective.joint import own
from .growing import grow
from .rest_fit import trigger_scan
from ..objective.uncertainty import at_noise
from .windowing import truncated

log = logging.getLogger(__name__)


def single_start(problem, w: np.ndarray, *, evals: int, first: float, seed: int,
                 journal: Optional[Path] = None, profile_points: int = 9, workers: int = 1,
                 hold_rest: bool = False) -> tuple:
    """(x, info): the joint `problem`'s start (module docstring); `w` the
    joint metric (1 / sigma^2 per column, the records side by side); `info`
    the first record's trail, each further record's trigger point and S on
    its first window, the simulations spent. `hold_rest`: the first
    record's complex holds its chain at rest (growing.grow)."""
    n = len(FORCE_CHANNELS)
    first_part = problem.parts[0]
    jr = None if journal is None else Path(journal).with_name(Path(journal).stem + ".single.jsonl")
    x0, info = grow(first_part, evals=evals, first=first, seed=seed, journal=jr, channel_weights=w[:n],
                    profile_points=profile_points, reset_unseen=True, keep_points=True, workers=workers,
                    hold_rest=hold_rest)
    # its point at the longest window still at the noise: past the onset of chaos the trail is carried
    # off (the first record of one layout-6 fit: 1.03 per sample up to 0.9 s, 7.5 on its whole 2.5 s)
    t0 = float(first_part.times[0])
    fits = [t for t in info["windows"]
            if at_noise(truncated(first_part, t0 + t["window_s"]), t["S_per_sample"] * n)] or info["windows"][:1]
    values = first_part.values(np.asarray(fits[-1]["x"], float))
    triggers, nfev = [], int(info["nfev"])
    for k, part in enumerate(problem.parts[1:], start=1):
        if TRIGGER not in part.free:   # a trigger point held at its value has nothing to search
            continue
        s, S, used = trigger_scan(part, values, w[k * n:(k + 1) * n], first)
        values[own(k)] = s
        triggers.append({"record": k, "trigger": s, "S_per_sample": S})
        nfev += used
        log.info("joint start: record %d's trigger point at %.4g m (S per sample %.3g on its first window)",
                 k, s, triggers[-1]["S_per_sample"])
    x = np.array([values[nm] for nm in problem.free], float)
    trail = [{k: v for k, v in t.items() if k != "x"} for t in info["windows"]]
    return x, {"single": trail, "from_window_s": float(fits[-1]["window_s"]), "triggers": triggers, "nfev": nfev}


__all__ = ["single_start", "trigger_scan"]
