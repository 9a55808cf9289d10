"""Identification over a growing window, as a pipeline of `lss identify`
(issue 17: the paper's ten variables free).

With all ten design variables free the published complex over a whole
start-stop stops in another valley (on one layout-1 record: 2.4 x f(truth)
after about 1500 CPU-s), and the staged pipeline's first stage lands the
drive in a wrong valley where the CoRs' start values ask it for what only
the CoRs can give (on one layout-5 sorter with three records: 30-50 x
f(truth), e_JA 0.56 off). The close loop's
base (identification.pipeline.growing) avoids both: the complex where the record is
still a smooth function of the design (its first 0.3 s), then
Levenberg-Marquardt carried along windows growing to the whole record.
What the first window cannot see at all (a start-stop's drive, saturated for
its first 0.3 s) is put back to its start value, the nominal one of
meta.json, before the windows grow (growing.grow, `reset_unseen`).

`identify_grown` wraps that into an IdentificationResult: the refinement and
the intervals on the whole record after growing, and, with `shrink`, the
window chosen by the shrink stage (identification.pipeline.windowing: while a CoR is
rough or the fit above the declared noise, the next shorter window of
LADDER, taken up from the grown trail's own point at that length). Nothing
of the truth is used.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
from tqdm.auto import tqdm

from ..objective.joint import JointProblem
from ..objective.parallel import pooled
from ..objective.problem import LINEARISABLE
from .edge_probe import edge_probes
from .growing import FIRST, grow, records_off
from .identify import IdentificationResult, local_stage, safe_nrmsd
from .joint_start import single_start
from .windowing import LADDER, shrink_window, truncated

log = logging.getLogger(__name__)

STARTS = ("complex", "single", "auto")   # where a joint problem's first window starts (joint_start)
STAGES = ("grown", "refined", "windows", "edges")   # what the progress bar counts, per run
PROFILE_POINTS = 9   # the profile of the least-determined variable on the first window (growing.grow)
WHOLE_TO_REFINEMENT = True   # the growing windows stop short of the whole record, which the refinement takes


def identify_grown(problem, *, max_evals: int = 400, seed=0, journal: Optional[Path] = None,
                   progress: bool = False, restarts: int = 0, refine_evals: int = 400,
                   uncertainty: bool = False, shrink: bool = False,
                   ladder: Sequence[float] = LADDER, first: float = FIRST, start: str = "auto",
                   hold_rest: bool = False, workers: int = 1, executor=None):
    """The problem (an IdentificationProblem or a joint one) identified over
    a growing window: `max_evals` complex evaluations on the first `first`
    seconds, the profile there, Levenberg-Marquardt over growing windows in
    the declared noise's metric (the likelihood's; else the first window's
    residual), then `refine_evals` simulations of refinement and the
    intervals on the whole record. `shrink`: shorter windows of `ladder`
    while `windowing.troubles` reports any (needs `uncertainty`). Returns an
    identify.IdentificationResult (`grown`: each window's S per sample;
    `windows`: the windows tried when shrinking). `start`: "complex" (the
    complex over every variable on the first window) or, for a joint problem,
    "single" (its first record alone, then the others' trigger points:
    identification.pipeline.joint_start) or "auto", the default (the complex, and
    where its first window stays above the declared noise the single start
    as well, the better of the two on that window going on: growing.grow's
    `retry`; on one record, or without a declared noise, the complex).
    `restarts`: while a record's S
    at the chosen window lies RETRY_Z sd above the declared noise
    (growing.records_off), the whole identification again with the next
    seed, at most `restarts` times; the better one goes on (`_better`).
    At the chosen window an identifiable CoR found near its box edge is
    refined again from the edge, kept where f ends lower
    (identification.pipeline.edge_probe; with `uncertainty` and `refine_evals`).
    `hold_rest`: the complex (and the single start's) holds what sets the
    chain at rest where a fit of it on the first window puts it
    (growing.grow, identification.pipeline.rest_fit). `progress`: a bar over
    the stages (the grown windows, the refinement
    and intervals, the shorter windows, the edge probes, each restart), with
    f after each. `workers` (local processes) or `executor` (a Dask
    client's, say): the complex's candidates and the Jacobians' columns side
    by side (identification.objective.parallel); the result is the serial
    run's, bit for bit."""
    if getattr(problem, "objective", "pointwise") not in LINEARISABLE:
        raise ValueError(f"grown identification: the {problem.objective} objective is not a sum of squares "
                         f"(use one of {', '.join(LINEARISABLE)})")
    if int(max_evals) < 1:
        raise ValueError(f"grown identification: max_evals = {max_evals} must be at least 1")
    if int(refine_evals) < 0:
        raise ValueError(f"grown identification: refine_evals = {refine_evals} must be 0 or more")
    if shrink and not uncertainty:
        raise ValueError("grown identification with shrink needs uncertainty=True: the roughness of the CoRs "
                         "decides the window")
    if start not in STARTS:
        raise ValueError(f"grown identification: start {start!r} is not one of {', '.join(STARTS)}")
    if int(restarts) < 0:
        raise ValueError(f"grown identification: restarts = {restarts} must be 0 or more")
    t0 = time.time()
    bar = tqdm(total=len(STAGES), desc=f"{problem.name}", unit="stage", leave=False) if progress else None
    once = dict(max_evals=max_evals, refine_evals=refine_evals, uncertainty=uncertainty, shrink=shrink,
                ladder=ladder, first=first, start=start, hold_rest=bool(hold_rest), tick=_ticker(bar),
                workers=max(1, int(workers)))
    try:
        with pooled(problem, workers, executor):
            res = _restarted(problem, seed, journal, int(restarts), once, bar, t0)
        res.problem.pool = None   # a shorter window's problem made inside: its pool is gone with the run
        return res
    finally:
        if bar is not None:
            bar.close()


def _ticker(bar):
    """A stage reporter: the bar moved on by one stage, with the stage's f (no bar: nothing)."""
    def tick(stage: str, f: float) -> None:
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(f"{stage}: f = {f:.4g}")
    return tick


def _restarted(problem, seed, journal, restarts: int, once: dict, bar, t0):
    """The grown identification, then while a record stays off the noise again with the next seed."""
    best = _once(problem, seed=seed, journal=journal, **once)
    if not restarts:
        return best
    tried = [_tried(seed, best)]
    kept = 0
    for k in range(1, restarts + 1):
        if not tried[kept]["records_off"]:
            break
        if bar is not None:
            bar.reset(total=len(STAGES))
            bar.set_description(f"{problem.name} (restart {k})")
        log.info("%s: records %s off the noise at the chosen window: again with seed %s", problem.name,
                 tried[kept]["records_off"], _next_seed(seed, k))
        jr = None if journal is None else Path(journal).with_name(Path(journal).stem + f".s{k}.jsonl")
        alt = _once(problem, seed=_next_seed(seed, k), journal=jr, **once)
        tried.append(_tried(_next_seed(seed, k), alt))
        if _better(problem, alt, tried[-1], best, tried[kept]):
            best, kept = alt, len(tried) - 1
    if len(tried) == 1:
        return best
    message = best.message + "; restarts: " + ", ".join(
        f"seed {t['seed']} f = {t['f']:.4g} at {t['window_s']:.3g} s"
        + (f" (records {t['records_off']} off the noise)" if t["records_off"] else "") for t in tried) \
        + f"; seed {tried[kept]['seed']} kept"
    nfev = sum(t["nfev"] for t in tried)
    return dataclasses.replace(best, restarts=len(tried) - 1, message=message, seconds=time.time() - t0,
                               nfev=nfev, evaluated=nfev)


def _tried(seed, res) -> dict:
    return {"seed": seed, "f": float(res.f), "window_s": float(res.problem.times[-1]), "records_off": _off(res),
            "nfev": int(res.nfev) + 1}


def _next_seed(seed, k: int):
    return seed + k if isinstance(seed, (int, np.integer)) else k


def _off(res) -> list:
    """The records off the declared noise at the result's own window (no
    declared noise: none)."""
    q = res.problem
    noise = getattr(q, "noise", None)
    if noise is None:
        return []
    try:
        return records_off(q, q.simulate(res.x), 1.0 / np.asarray(noise, float) ** 2)
    except Exception:   # a point that does not simulate is off everywhere
        return [-1]


def _better(problem, b, tb: dict, a, ta: dict) -> bool:
    """Whether identification b (its entry `tb`) is better than a: no record
    off the noise at its window where a has one; else (both or neither) a
    lower f on the shorter of their two windows."""
    if bool(ta["records_off"]) != bool(tb["records_off"]):
        return not tb["records_off"]
    s = min(ta["window_s"], tb["window_s"])
    q = truncated(problem, s) if s < float(problem.times[-1]) - 1e-9 else problem
    return _safe_f(q, b.x) < _safe_f(q, a.x)


def _safe_f(q, x) -> float:
    try:
        return float(q(np.asarray(x, float)))
    except Exception:
        return float("inf")


def _once(problem, *, max_evals, seed, journal, refine_evals, uncertainty, shrink, ladder, first, start, hold_rest,
          tick, workers):
    """One grown identification (identify_grown without restarts)."""
    t0 = time.time()
    x0 = problem.x0_vector()
    if x0 is None:
        x0 = np.array([0.5 * (lo + hi) for lo, hi in problem.bounds_array])
    f0 = float(problem(x0))
    noise = getattr(problem, "noise", None)
    w = None if noise is None else 1.0 / np.asarray(noise, float) ** 2
    x_start, started = None, None
    if start == "single" and isinstance(problem, JointProblem) and w is not None:
        x_start, started = single_start(problem, w, evals=int(max_evals), first=first, seed=seed, journal=journal,
                                        profile_points=PROFILE_POINTS, workers=workers, hold_rest=hold_rest)
    retry, box = None, {}
    if start == "auto" and isinstance(problem, JointProblem) and w is not None:
        def single_retry():
            box["x"], box["info"] = single_start(problem, w, evals=int(max_evals), first=first, seed=seed,
                                                 journal=journal, profile_points=PROFILE_POINTS, workers=workers,
                                                 hold_rest=hold_rest)
            return box["x"], box["info"]["nfev"]
        retry = single_retry
    # the refinement is Levenberg-Marquardt on the whole record in the windows' own metric when the
    # objective is the declared noise's likelihood: the whole record is then left to it
    same_metric = w is not None and getattr(problem, "objective", "pointwise") == "likelihood"
    x, info = grow(problem, evals=int(max_evals), first=first, seed=seed, journal=journal,
                   channel_weights=w, profile_points=PROFILE_POINTS, keep_points=True, reset_unseen=True,
                   start=x_start, retry=retry, workers=workers, hold_rest=hold_rest,
                   whole=not (WHOLE_TO_REFINEMENT and same_metric and int(refine_evals) > 0))
    if started is not None:
        info["nfev"] += started["nfev"]
    elif info.get("retry") and info["retry"]["taken"]:
        started = box["info"]
    f = float(problem(x))
    tick("grown", f)   # on the whole record: the last window may be shorter (grow's `whole`)
    duration = float(problem.times[-1])
    below = [float(s) for s in ladder if float(s) < duration - 1e-9]
    shorter = max(below) if shrink and uncertainty and below else None
    local = local_stage(problem, x, f, int(refine_evals), uncertainty, journal, shorter=shorter)
    if local.get("f", np.inf) < f:
        x, f = np.asarray(local["x"], float), float(local["f"])
    nfev = int(info["nfev"]) + 1 + int((local.get("refined") or {}).get("nfev", 0))
    tick("refined", f)
    trail = [{k: v for k, v in t.items() if k != "x"} for t in info["windows"]]
    message = (f"grown over {len(trail)} windows to {trail[-1]['window_s']:.3g} s "
               f"(S per sample {trail[0]['S_per_sample']:.3g} on the first, {trail[-1]['S_per_sample']:.3g} "
               f"on the last)")
    if started is not None:
        taken = next(t for t in started["single"] if t["window_s"] == started["from_window_s"])
        message += (f"; started from the first record alone (its point at {taken['window_s']:.3g} s, S per sample "
                    f"{taken['S_per_sample']:.3g}) and the others' trigger points at "
                    + ", ".join(f"{t['trigger']:.4g}" for t in started["triggers"]) + " m")
    if info.get("retry") and not info["retry"]["taken"]:
        message += (f"; the first record alone tried and left (S per sample {info['retry']['S_per_sample_retry']:.3g}"
                    f" on the first window against the complex's {info['retry']['S_per_sample_complex']:.3g})")
    if info.get("unseen"):
        message += f"; unseen on the first window, started from their start values: {', '.join(info['unseen'])}"
    if local.get("refined"):
        message += f"; refined to f = {f:.4g} in {local['refined']['nfev']} simulations"
    res = IdentificationResult.of(problem, x0, f0, x, f, nfev=nfev, message=message, history_f=[f0, f],
                                  seconds=time.time() - t0, refined=local.get("refined"),
                                  intervals=local.get("intervals"), grown=trail)
    if shrink:
        res = shrink_window(problem, res, info["windows"], ladder, int(refine_evals), journal, t0)
    tick("windows", res.f)
    res = _from_edges(res, int(refine_evals), journal)
    tick("edges", res.f)
    return res


def _from_edges(res, refine_evals, journal):
    """`res` after the edge probes at its own window (identification.pipeline.edge_probe)."""
    q = res.problem
    jr = None if journal is None else Path(journal).with_name(Path(journal).stem + f".w{float(q.times[-1]):g}.jsonl")
    x, f, ivs, probes = edge_probes(q, res.x, float(res.f), res.intervals, refine_evals, jr)
    if not probes:
        return res
    extra = sum(p["nfev"] for p in probes)
    kept = [p for p in probes if p["kept"]]
    message = res.message + "; from the box edge: " + ", ".join(
        f"{p['name'].split('.')[-1]} {p['from']:.3g} -> {p['edge']:g}: f = {p['f']:.6g}" for p in probes) \
        + (f" ({kept[0]['name'].split('.')[-1]} kept, at {kept[0]['to']:.3g})" if kept else " (none lower)")
    if not kept:
        return dataclasses.replace(res, nfev=res.nfev + extra, evaluated=res.evaluated + extra, message=message)
    return dataclasses.replace(res, x=np.asarray(x, float), f=float(f), H=safe_nrmsd(q, x), intervals=ivs,
                               nfev=res.nfev + extra, evaluated=res.evaluated + extra, message=message,
                               history_f=np.append(res.history_f, f))


__all__ = ["identify_grown"]
