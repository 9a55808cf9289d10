"""The campaign: every measurement x every contact model, in parallel.

Each identification runs as one task (serial Complex-RF inside, one FMU
instance per worker process) on local processes or on an existing Dask
cluster. Results are written atomically as each finishes
(`results/<id>_<model>.json`); every evaluation is journaled
(`journals/<id>_<model>.jsonl`). A campaign killed at any moment and started
again skips what is finished and resumes the rest from its journal: the same
results, no evaluation lost or counted twice.

    lss campaign DATA_DIR --models HC,HW,LW,LN --out DIR [--scheduler ADDRESS]
"""
from __future__ import annotations

import json
import logging
import math
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

from lss_fmu.atomic import write_json_atomic

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Task:
    measurement: str     # folder
    model: str
    out: str             # campaign folder
    max_evals: int
    seed: int
    window: Optional[float]
    settle: Optional[float]
    free: Optional[tuple]
    tare: bool = False   # take out zero errors within the transducer's declared offset (from_measurement)
    restarts: int = 0    # identify(restarts=...)
    presolve: int = 0    # identify(presolve=...): the layout-dependent variables first
    refine_evals: int = 0   # identify(refine_evals=...): Levenberg-Marquardt after the complex
    uncertainty: bool = False   # identify(uncertainty=...): an interval per free variable
    objective: str = "pointwise"  # from_measurement(objective=...)
    staged: bool = False         # identification.staged instead of identify
    shrink: bool = False         # identification.windowing: shorter windows while a CoR is rough
    grown: bool = False          # identification.identify_grown: the complex on the first 0.3 s, windows grown

    @property
    def key(self) -> str:
        return f"{Path(self.measurement).name}_{self.model}"

    @property
    def result_path(self) -> Path:
        return Path(self.out) / "results" / f"{self.key}.json"

    @property
    def journal_path(self) -> Path:
        return Path(self.out) / "journals" / f"{self.key}.jsonl"


def run_task(task: Task) -> dict:
    """One identification (in a worker); writes its result file atomically."""
    from lss_fmu.measurement import load_measurement
    from .problem import from_measurement
    from .staged import run
    meas = load_measurement(task.measurement)
    problem = from_measurement(meas, task.model, free=task.free, window=task.window, settle=task.settle,
                               tare=task.tare, objective=task.objective)
    task.journal_path.parent.mkdir(parents=True, exist_ok=True)
    c0 = time.process_time()
    try:
        res = run(problem, task.staged, task.shrink, task.grown, max_evals=task.max_evals, seed=task.seed,
                  journal=task.journal_path, progress=False, restarts=task.restarts, presolve=task.presolve,
                  refine_evals=task.refine_evals, uncertainty=task.uncertainty)
    finally:
        problem.sim.close()
    out = res.to_dict()
    out["cpu_s"] = time.process_time() - c0   # this run's (a resumed one: the rest of it)
    out.update({"wheel_type": meas.meta.get("wheel_type"), "coupling_type": meas.meta.get("coupling_type"),
                "number": meas.meta.get("number"), "measurement_dir": str(task.measurement)})
    write_json_atomic(task.result_path, out)
    return out


def run_campaign(data_dir: Path, models: Sequence[str], out: Path, *, workers: int = 2,
                 scheduler: Optional[str] = None, max_evals: int = 5000, seed: int = 0,
                 window: Optional[float] = None, settle: Optional[float] = None, free: Optional[tuple] = None,
                 progress: bool = True, client=None, tare: bool = False, restarts: int = 0, presolve: int = 0,
                 refine_evals: int = 0, uncertainty: bool = False, objective: str = "pointwise",
                 staged: bool = False, shrink: bool = False, grown: bool = False) -> list[dict]:
    """Run what is not finished yet; return all results (finished before or now)."""
    from lss_fmu.design import parse_model
    from lss_fmu.measurement import find_measurements
    models = [parse_model(m) for m in models]
    out = Path(out)
    if int(restarts) < 0:
        raise ValueError(f"restarts = {restarts}: must be 0 or more")
    # refused before anything runs: each task would fail alone, after the pool had started
    if int(max_evals) < 1:
        raise ValueError(f"max_evals = {max_evals}: must be at least 1")
    if int(refine_evals) < 0:
        raise ValueError(f"refine_evals = {refine_evals}: must be 0 or more")
    if window is not None and not (math.isfinite(float(window)) and float(window) > 0):
        raise ValueError(f"window = {window} s: must be a positive number of seconds")
    if scheduler is None and client is None and int(workers) < 1:
        raise ValueError(f"workers = {workers}: must be at least 1")
    if shrink and not uncertainty:
        raise ValueError("shrink needs uncertainty: the roughness of the CoRs at the optimum decides the window")
    if staged and grown:
        raise ValueError("choose one pipeline: staged or grown, not both")
    out.mkdir(parents=True, exist_ok=True)
    folders = find_measurements(data_dir)
    if not folders:
        raise FileNotFoundError(f"{data_dir} holds no measurement (no meta.json in it or below)")
    tasks = [Task(str(p), m, str(out), max_evals, seed, window, settle, free, tare, int(restarts), int(presolve),
                  int(refine_evals), bool(uncertainty), objective, bool(staged), bool(shrink), bool(grown))
             for p in folders for m in models]
    twice = sorted({t.key for t in tasks if sum(u.key == t.key for u in tasks) > 1})
    if twice:  # results are filed by folder name
        raise ValueError(f"{data_dir}: measurement folders share a name ({', '.join(twice[:5])}); a campaign "
                         f"files its results by folder name, so give each measurement its own")
    write_json_atomic(out / "campaign.json", {"data_dir": str(data_dir), "models": list(models),
                                              "max_evals": max_evals, "seed": seed, "window": window,
                                              "settle": settle, "free": list(free) if free else None,
                                              "tare": tare, "restarts": int(restarts), "presolve": int(presolve),
                                              "refine_evals": int(refine_evals), "uncertainty": bool(uncertainty),
                                              "objective": objective, "staged": bool(staged),
                                              "shrink": bool(shrink), "grown": bool(grown),
                                              "tasks": [t.key for t in tasks]})
    todo = [t for t in tasks if not t.result_path.exists()]
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc="campaign", unit="id")
    best = {}

    def done(r: dict) -> None:
        best[r["measurement"]] = min(best.get(r["measurement"], float("inf")), r["f"])
        if bar:
            bar.update(1)
            bar.set_postfix_str(f"{r['measurement']}/{r['model']} f={r['f']:.3g}")

    if todo:
        if client is None and scheduler:
            from dask.distributed import Client
            client = Client(scheduler)
        if client is not None:
            from dask.distributed import as_completed as dask_completed
            futures = [client.submit(run_task, t, key=f"lss-{t.key}-{seed}", pure=False) for t in todo]
            for fut in dask_completed(futures):
                done(fut.result())
        else:
            with ProcessPoolExecutor(max(1, workers)) as ex:
                futures = [ex.submit(run_task, t) for t in todo]
                for fut in as_completed(futures):
                    done(fut.result())
    if bar:
        bar.close()
    return [json.loads(t.result_path.read_text()) for t in tasks]
