"""The identification's front door: records of one sorter and a contact model
in, an IdentificationResult out, the method chosen by the records.

- **Transient records** (start-up, start-stop, speed step, stop): the
  pipeline of the recovery table. The first `window` seconds of every record
  (the whole record if shorter), each force over the sensor's declared noise
  (the likelihood objective), zero errors within the transducer's tolerance
  taken out; the complex on the first 0.3 s, Levenberg-Marquardt carried
  along windows growing to the whole window, the refinement and an interval
  per variable, shorter windows while a CoR is rough, restarts while a record
  stays off the noise (identification.pipeline.identify_grown). Several records are
  fitted jointly: one design, each record its own trigger point.
- **Steady running**: the chain is chaotic there (docs/identification.md), so
  no pointwise fit can find the CoRs; the complex fits the force statistics
  (spectra, amplitude distributions), and the result says that the CoRs are
  not identifiable from such a record.

Every choice comes from `Settings` (defaults that work; an expert's TOML),
and the settings used are written into the result.
"""
from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np

from ..objective.joint import JointProblem
from ..objective.problem import from_measurement
from .identify import identify
from .identify_grown import identify_grown
from .settings import Settings

log = logging.getLogger(__name__)

STEADY_NOTE = ("steady running: the chain is chaotic, a simulation and the record decorrelate within about "
               "half a second whatever the parameters, so the CoRs are not identifiable from this record; "
               "the values fit its force statistics only (record a start-stop to identify them)")


class RecordsError(ValueError):
    """Records that cannot be identified together; names the record and what differs."""


def _sorter(meas) -> dict:
    meta = meas.meta or {}
    return {"layout": meas.layout_for_fmu, "wheel type": meta.get("wheel_type"),
            "coupling type": meta.get("coupling_type")}


def check_records(records: Sequence) -> None:
    """One sorter, one protocol: a clear error naming the record otherwise."""
    if not records:
        raise RecordsError("no record given")
    first = records[0]
    ref, proto = _sorter(first), first.protocol.name
    for m in records[1:]:
        for key, value in _sorter(m).items():
            if value != ref[key]:
                raise RecordsError(f"{m.path or m.id}: {key} {value!r} differs from {first.path or first.id}'s "
                                   f"{ref[key]!r}: records identified together must come from one sorter")
        if m.protocol.name != proto:
            raise RecordsError(f"{m.path or m.id}: protocol {m.protocol.name!r} differs from "
                               f"{first.path or first.id}'s {proto!r}: identify records of one protocol together")


def method_of(records: Sequence) -> str:
    """'grown' for transient records, 'statistics' for steady running."""
    return "grown" if records[0].protocol.transient else "statistics"


def _span(meas) -> float:
    t = np.asarray(meas.time, float)
    return float(t[-1] - t[0]) if len(t) else 0.0


def build_problem(records: Sequence, model: str, settings: Settings, sim=None,
                  survey: Optional[Mapping[str, object]] = None):
    """The problem the front door fits: one record's IdentificationProblem, or
    several records' JointProblem, on the method's objective and window.
    `survey`: FMU values of a survey of the sorter (lss_fmu.survey.load_survey:
    its as-built track, mass factor, guide gap) in place of the design's."""
    check_records(records)
    method = method_of(records)
    kw = dict(free=settings.free, fixed=dict(survey or {}))
    if method == "grown":
        span = min(_span(m) for m in records)
        kw.update(window=min(settings.window, span), tare=settings.tare, objective="likelihood")
    else:
        kw.update(objective="statistics")
    parts = [from_measurement(m, model, sim=sim if k == 0 else None, **kw) for k, m in enumerate(records)]
    for p in parts:
        p.sensitivities = settings.sensitivities
    return parts[0] if len(parts) == 1 else JointProblem(parts)


def identify_records(records: Sequence, model: str, settings: Optional[Settings] = None, *, seed=0,
                     journal: Optional[Path] = None, progress: bool = False, workers: int = 1, executor=None,
                     problem=None, survey: Optional[Mapping[str, object]] = None):
    """Identify `records` (loaded measurements of one sorter and protocol) with
    contact `model`; returns an identify.IdentificationResult whose `settings`
    and `method` say how (to_dict() carries both). `problem`: one already
    built by build_problem (else it is built here, with `survey`, which the
    result then names). `workers` local
    processes, or an `executor` (a Dask client's get_executor()), run a
    transient identification's independent simulations side by side, the
    result the serial one's; a steady record's complex takes `workers`."""
    settings = settings or Settings()
    if problem is None:
        problem = build_problem(records, model, settings, survey=survey)
    method = method_of(records)
    if method == "grown":
        res = identify_grown(problem, max_evals=settings.max_evals, seed=seed, journal=journal, progress=progress,
                             restarts=settings.restarts, refine_evals=settings.refine_evals, uncertainty=True,
                             shrink=settings.shrink, start=settings.start, first=settings.first_window,
                             hold_rest=settings.hold_rest, workers=workers, executor=executor)
    else:
        res = identify(problem, max_evals=settings.steady_evals, seed=seed, journal=journal, progress=progress,
                       workers=workers)
        res = dataclasses.replace(res, message=f"{res.message}; {STEADY_NOTE}")
    return dataclasses.replace(res, settings=settings.to_dict(), method=method,
                               records=[str(m.path or m.id) for m in records],
                               survey=None if survey is None else dict(survey))
