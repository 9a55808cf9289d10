"""One identification: a problem, Complex-RF, a journal, a result file.

Every evaluation is appended to a journal (one JSON line, flushed) as soon as
it is known. Run again after an interruption, the same seed makes the
optimiser ask for the same points in the same order, and the journal answers
them without simulating: the result is the same and no evaluation is lost or
counted twice. The result is written atomically.

With `workers` > 1 the parallel Complex-RFP (speculative strategy) asks for
exactly the points the serial method would use, plus speculative ones it may
discard; the journal holds all of them. The result's history is the
optimiser's own: the evaluations it used, in the order it used them
(`ComplexHistory.used_order`), and its iteration table, so a run with workers
and a serial run from the same seed give the same history, figure and JSON.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from lss_fmu.atomic import write_json_atomic
from lss_fmu.design import CORS, LAYOUT_DEPENDENT, symbol
from lss_fmu.variables import FORCE_CHANNELS

from ..objective.problem import LINEARISABLE, IdentificationProblem
from ..objective.uncertainty import Interval, above_noise, at_noise, intervals, noise_bound
from ..optim.complex_rf import minimize_complex
from ..optim.complex_rfp import minimize_complex_parallel
from ..optim.journal import Journal, JournaledObjective, journaled_map, point_key
from ..optim.optim_result import ComplexResult, jsonable
from .refine import refine


log = logging.getLogger(__name__)


@dataclass
class IdentificationResult:
    problem: IdentificationProblem
    x0: np.ndarray
    f0: float
    H0: np.ndarray
    x: np.ndarray
    f: float
    H: np.ndarray
    nfev: int
    evaluated: int
    replayed: int
    message: str
    history_f: np.ndarray            # f of the used evaluations, in the order the method used them
    seconds: float
    iterations: dict = None          # the optimiser's iteration table (ComplexHistory.iterations)
    nfev_total: int = 0              # all evaluations, incl. speculative ones the method discarded
    nrounds: int = 0                 # wall-clock rounds (batches of evaluations)
    workers: int = 1
    optimizer: Optional[ComplexResult] = None  # the (last) optimiser run's result, with its full history
    restarts: int = 0                # restarts made (see identify)
    refined: Optional[dict] = None   # the local refinement: f before and after, simulations
    presolved: Optional[dict] = None  # the first stage (identify(presolve=...)): f0, f, evaluations, values
    intervals: Optional[list] = None  # identification.objective.uncertainty.Interval per free variable
    windows: Optional[list] = None   # identification.pipeline.windowing: every window tried, its f and troubles
    grown: Optional[list] = None     # identification.pipeline.identify_grown: each growing window's S per sample
    method: Optional[str] = None     # identification.pipeline.driver: "grown" or "statistics"
    settings: Optional[dict] = None  # identification.pipeline.driver: the settings used (Settings.to_dict)
    records: Optional[list] = None   # identification.pipeline.driver: the record folders fitted
    survey: Optional[dict] = None    # identification.pipeline.driver: the survey's FMU values given (lss_fmu.survey)

    @classmethod
    def of(cls, problem, x0, f0: float, x, f: float, *, nfev: int, message: str, history_f, seconds: float,
           evaluated: Optional[int] = None, replayed: int = 0, **more) -> "IdentificationResult":
        """The one constructor of a result: the channel errors H0 and H are
        the problem's at x0 and x (NaN where a point does not simulate)."""
        return cls(problem, np.asarray(x0, float), float(f0), safe_nrmsd(problem, x0), np.asarray(x, float),
                   float(f), safe_nrmsd(problem, x), int(nfev), int(nfev if evaluated is None else evaluated),
                   int(replayed), message, np.asarray(history_f, float), float(seconds), **more)

    def to_dict(self) -> dict:
        p = self.problem
        return {
            "measurement": p.name, "model": p.model, "layout": p.layout,
            "free": list(p.free), "bounds": {k: list(p.bounds[k]) for k in p.free},
            "x0": dict(zip(p.free, map(float, self.x0))), "f0": self.f0,
            "nrmsd0": dict(zip(FORCE_CHANNELS, map(float, self.H0))),
            "x": dict(zip(p.free, map(float, self.x))), "f": self.f,
            "nrmsd": dict(zip(FORCE_CHANNELS, map(float, self.H))),
            "values": {symbol(k): v for k, v in p.values(self.x).items()},
            "nfev": self.nfev, "simulated": self.evaluated, "replayed": self.replayed,
            "message": self.message, "history_f": list(map(float, self.history_f)),
            "iterations": jsonable(self.iterations or {}),
            "nfev_total": self.nfev_total, "discarded": self.nfev_total - self.nfev,
            "rounds": self.nrounds, "workers": self.workers, "restarts": self.restarts,
            "seconds": self.seconds, "window_s": float(p.times[-1]),
            "protocol": p.protocol.to_meta(), "tolerance": p.tolerance,
            "refined": self.refined, "presolved": self.presolved, "windows": self.windows,
            "grown": self.grown,
            "interval": None if self.intervals is None else {
                symbol(iv.name): iv.to_dict() for iv in self.intervals},
            "method": self.method, "settings": self.settings, "records": self.records, "survey": self.survey,
        }


REFINE_STEP = 0.01     # the refinement's difference step, of each bound range: well above the solver's error
RESTART_WIDTH = 0.15   # half-width of a restart's box, as a share of each variable's bound range


def identify(problem: IdentificationProblem, *, max_evals: int = 5000, seed=0,
             journal: Optional[Path] = None, progress: bool = True, f_tol: float = 1e-6,
             x_tol: float = 1e-4, workers: int = 1, restarts: int = 0, refine_evals: int = 0,
             uncertainty: bool = False, presolve: int = 0) -> IdentificationResult:
    """Complex-RF on the problem (the parallel variant with `workers` > 1,
    each worker process with its own FMU instance), then optionally a local
    refinement and the intervals of the result.

    `restarts`: when the complex has converged (function or parameter spread)
    before `max_evals`, start a new complex in a box of +-RESTART_WIDTH of the
    bound ranges around the best point (the best point in it), up to this many
    times, until the budget is used. The Complex contracts onto a ridge of a
    rough objective long before the minimum (the release transient: f stops at
    20x the noise floor); a fresh, smaller complex picks the descent up again.
    0 is the method as published.

    `presolve`: evaluations of a first complex in which only the
    layout-dependent variables (speed, pretension, rolling resistance,
    trigger, gains) are free, the CoRs held at their start values; the main
    complex then starts from its best point. Those variables move the
    objective tens of times more than the CoRs do (they set the force
    levels and the speed history; the CoRs shape oscillations on top), so a
    complex with all ten free first spends itself on them and contracts
    with the CoRs where they happened to be. 0: none.

    `refine_evals`: after the complex, Levenberg-Marquardt on the objective's
    own residual from its best point (identification.pipeline.refine), at most this
    many simulations on top of `max_evals`: the complex finds the basin and
    contracts before its bottom; on a smooth objective (a transient record at
    tolerance 1e-6) a few Gauss-Newton steps reach it. `uncertainty`: an
    interval for every free variable at the result (identification.objective.uncertainty,
    2 simulations per variable). Both are kept beside the journal and taken
    from there on a resume.

    `nfev` and `history_f` count the evaluations the method used (`max_evals`
    limits them, over all restarts); with workers, `nfev_total` adds the
    speculative ones it discarded. An exception of the objective, in this
    process or a worker, is a bad point with a logged line, never the end of
    the run. (The ten-variable problem ordered the other way:
    identification.staged.)"""
    if int(restarts) < 0:
        raise ValueError(f"restarts = {restarts}: must be >= 0")
    t0 = time.time()
    pre = _presolve(problem, presolve, seed, journal, progress, f_tol, x_tol, workers)
    if pre is not None:
        problem = dataclasses.replace(problem, x0={**(problem.x0 or {}), **pre.problem.values(pre.x)})
    jr = Journal(journal)
    jr.vouch(problem, len(problem.bounds_array), getattr(problem, "bad_value", None))   # not another objective's journal
    x0 = problem.x0_vector()
    if x0 is None:
        x0 = np.array([0.5 * (lo + hi) for lo, hi in problem.bounds_array])
    lo, hi = np.array(problem.bounds_array, float).T
    n_points = len(lo) + 2
    runs, evaluated = [], 0
    try:
        bounds, start, budget = problem.bounds_array, x0, int(max_evals)
        while True:
            r = len(runs)
            res, n_sim = _complex_run(problem, jr, bounds, start, budget, seed if r == 0 else [seed, r],
                                      progress, f_tol, x_tol, workers)
            runs.append(res)
            evaluated += n_sim
            budget -= int(res.nfev_used)
            if r >= restarts or budget < n_points or not res.success:
                break
            best = min(runs, key=lambda q: q.fun)
            half = RESTART_WIDTH * (hi - lo)
            bounds = list(zip(np.maximum(lo, best.x - half), np.minimum(hi, best.x + half)))
            start = np.asarray(best.x, float)
        last, best = runs[-1], min(runs, key=lambda q: q.fun)
        history_f = np.concatenate([np.asarray(q.history.f, float)[q.history.used_order()] for q in runs])
        f0 = float(history_f[0])  # x0 is the first point of the initial complex
        x_best, f_best = np.asarray(best.x, float), float(best.fun)
        local = local_stage(problem, x_best, f_best, refine_evals, uncertainty, journal)
        if local.get("f", np.inf) < f_best:
            x_best, f_best = np.asarray(local["x"], float), float(local["f"])
    finally:
        jr.close()
    message = last.message if len(runs) == 1 else f"{last.message} (after {len(runs) - 1} restarts)"
    if local.get("refined"):
        message += f"; refined to f = {f_best:.4g} in {local['refined']['nfev']} simulations"
    return IdentificationResult.of(problem, x0, f0, x_best, f_best, nfev=int(sum(q.nfev_used for q in runs)),
                                evaluated=evaluated, replayed=jr.replayed, message=message, history_f=history_f,
                                seconds=time.time() - t0, iterations=_joined_iterations(runs),
                                nfev_total=int(sum(q.nfev for q in runs)), nrounds=int(sum(q.nrounds for q in runs)),
                                workers=max(1, int(workers)), optimizer=last, restarts=len(runs) - 1,
                                refined=local.get("refined"), intervals=local.get("intervals"),
                                presolved=None if pre is None else {
                                    "f0": pre.f0, "f": pre.f, "nfev": pre.nfev,
                                    "x": dict(zip(pre.problem.free, map(float, pre.x)))})


def _presolve(problem, evals: int, seed, journal, progress, f_tol, x_tol, workers):
    """The first stage of `identify(presolve=...)`: the layout-dependent
    variables alone (journal: JOURNAL.presolve.jsonl). None when there is
    nothing to do: no budget, or no CoR and no other variable free."""
    free = tuple(n for n in problem.free if n in LAYOUT_DEPENDENT)
    if evals <= 0 or not free or len(free) == len(problem.free):
        return None
    stage = dataclasses.replace(problem, free=free)
    side = Path(journal).with_suffix(".presolve.jsonl") if journal else None
    return identify(stage, max_evals=evals, seed=[seed, 1000] if isinstance(seed, int) else seed, journal=side,
                    progress=progress, f_tol=f_tol, x_tol=x_tol, workers=workers)


def local_stage(problem, x, f, refine_evals: int, uncertainty: bool, journal: Optional[Path],
                shorter: Optional[float] = None) -> dict:
    """The refinement and the intervals after the complex, kept in
    JOURNAL.local.json (atomically) for the resume of an interrupted run.
    `shorter`: the end (s) of the shorter window that follows where a CoR is
    rough here and that window could claim it (the shrink stage,
    identification.pipeline.windowing.troubles). The refinement then stops
    at its start where its first Jacobian finds such a CoR (refine's
    stop_rough and within): the intervals would call it rough after any
    refinement. The intervals say which variables that window could claim.
    It also stops where its pace could not bring the fit down to the
    declared noise within its budget (refine's `reach`): such a window is
    cut. A fit left above the noise there claims no interval, and none is
    differenced (uncertainty.above_noise)."""

    if getattr(problem, "objective", "pointwise") not in LINEARISABLE and (refine_evals > 0 or uncertainty):
        # both linearise the residual sample by sample: they mean nothing for a statistical objective
        log.warning("%s: no refinement and no intervals with the %s objective", problem.name, problem.objective)
        return {}
    if refine_evals <= 0 and not uncertainty:
        return {}
    side = Path(journal).with_suffix(".local.json") if journal else None
    # f at the start, as this objective gives it: a refinement kept from an objective that has changed
    # since (journal.vouch) is not taken up
    key = {"start": point_key(x), "f_start": float(f), "refine_evals": int(refine_evals),
           "uncertainty": bool(uncertainty), **({"shorter": float(shorter)} if shorter is not None else {})}
    if side is not None and side.exists():
        try:
            kept = json.loads(side.read_text())
            if kept.get("key") == key:
                out = dict(kept["result"])
                if out.get("intervals") is not None:
                    out["intervals"] = [Interval(**{**iv, "sd": float("inf") if iv.get("sd") is None else iv["sd"]})
                                        for iv in out["intervals"]]
                return out
        except (ValueError, KeyError, TypeError):
            pass  # unreadable: computed again
    out, sim, lin = {}, None, None
    if refine_evals > 0:
        watch = [k for k, n in enumerate(problem.free) if n in CORS] if shorter is not None else []
        ref = refine(problem, x, max_evals=int(refine_evals), rel_step=REFINE_STEP, f_rtol=1e-4, central=True,
                     stop_rough=watch, within=shorter, reach=noise_bound(problem))
        out["refined"] = {"f_start": float(f), "f": float(ref.f), "nfev": int(ref.nfev),
                          "iterations": int(ref.iterations)}
        if ref.rough:
            out["refined"]["rough_at_start"] = [problem.free[k] for k in ref.rough]
        if ref.short:
            out["refined"]["short_of_noise"] = True
        if ref.f < f:
            out["x"], out["f"], sim = ref.x.tolist(), float(ref.f), ref.sim
            x = ref.x
        if ref.at is not None and ref.steps is not None:
            lin = (ref.at, ref.steps)   # the intervals take it where x is inside its stencil
    if uncertainty and shorter is not None and at_noise(problem, out.get("f", f)) is False:
        # above the noise with a shorter window to follow: the window is cut (windowing.troubles)
        out["intervals"] = above_noise(problem, x)
    elif uncertainty:
        try:
            out["intervals"] = intervals(problem, x, sim, linearised=lin, shorter=shorter)
        except Exception as exc:  # no intervals rather than no result
            log.warning("%s: intervals failed: %s", problem.name, exc)
    if side is not None:
        kept = dict(out)
        if kept.get("intervals") is not None:
            kept["intervals"] = [{"name": iv.name, **iv.to_dict()} for iv in kept["intervals"]]
        write_json_atomic(side, {"key": key, "result": jsonable(kept)})
    return out


def _complex_run(problem, jr: Journal, bounds, x0, budget: int, seed, progress: bool, f_tol: float,
                 x_tol: float, workers: int) -> tuple:
    """One Complex-RF (or RFP) run behind the journal: (result, evaluations simulated)."""
    opts = dict(x0=x0, max_evals=budget, seed=seed, progress=progress, f_tol=f_tol, x_tol=x_tol)
    if workers > 1:
        with ProcessPoolExecutor(workers) as ex:
            mapper = journaled_map(jr, ex)
            res = minimize_complex_parallel(problem, bounds, n_parallel=workers,
                                            strategy="speculative", map_fn=mapper, **opts)
        return res, mapper.counter["evaluated"]
    obj = JournaledObjective(problem, jr)
    res = minimize_complex(obj, bounds, **opts)
    return res, obj.evaluated


def _joined_iterations(runs: list) -> dict:
    """The iteration tables of successive runs as one: iterations, rounds and
    evaluation counts continue from the previous run's."""
    out: dict = {}
    it = rnd = nfev = 0
    for q in runs:
        tab = q.history.iterations
        shift = {"iteration": it, "round": rnd, "nfev": nfev}
        for k, v in tab.items():
            out.setdefault(k, []).append(np.asarray(v) + shift.get(k, 0))
        if len(tab.get("iteration", [])):
            it = int(out["iteration"][-1][-1]) + 1
            rnd = int(out["round"][-1][-1]) + 1
        nfev += int(q.nfev_used)
    return {k: np.concatenate(v) for k, v in out.items()}


def safe_nrmsd(problem: IdentificationProblem, x) -> np.ndarray:
    try:
        return problem.channel_errors(x)
    except Exception:
        return np.full(len(FORCE_CHANNELS), np.nan)
