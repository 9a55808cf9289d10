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

import argparse
import json
import logging
import sys
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
    settle: float
    free: Optional[tuple]
    tare: bool = False   # take out zero errors within the transducer's declared offset (from_measurement)
    restarts: int = 0    # identify(restarts=...)

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
    from .identify import identify
    from .problem import from_measurement
    meas = load_measurement(task.measurement)
    problem = from_measurement(meas, task.model, free=task.free, window=task.window, settle=task.settle,
                               tare=task.tare)
    task.journal_path.parent.mkdir(parents=True, exist_ok=True)
    res = identify(problem, max_evals=task.max_evals, seed=task.seed, journal=task.journal_path, progress=False,
                   restarts=task.restarts)
    out = res.to_dict()
    out.update({"wheel_type": meas.meta.get("wheel_type"), "coupling_type": meas.meta.get("coupling_type"),
                "number": meas.meta.get("number"), "measurement_dir": str(task.measurement)})
    write_json_atomic(task.result_path, out)
    return out


def find_measurements(data_dir: Path) -> list[Path]:
    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise FileNotFoundError(f"no such measurement folder: {data_dir}")
    found = sorted(p.parent for p in data_dir.glob("*/meta.json") if p.parent.name != "answers")
    if not found:
        raise FileNotFoundError(f"{data_dir} holds no measurement (no */meta.json)")
    return found


def run_campaign(data_dir: Path, models: Sequence[str], out: Path, *, workers: int = 2,
                 scheduler: Optional[str] = None, max_evals: int = 5000, seed: int = 0,
                 window: Optional[float] = None, settle: float = 4.0, free: Optional[tuple] = None,
                 progress: bool = True, client=None, tare: bool = False, restarts: int = 0) -> list[dict]:
    """Run what is not finished yet; return all results (finished before or now)."""
    from lss_fmu.variables import CONTACT_MODELS
    for m in models:
        if m not in CONTACT_MODELS:
            raise ValueError(f"unknown contact model {m!r}: use one of {', '.join(CONTACT_MODELS)}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if int(restarts) < 0:
        raise ValueError(f"restarts = {restarts}: must be 0 or more")
    tasks = [Task(str(p), m, str(out), max_evals, seed, window, settle, free, tare, int(restarts))
             for p in find_measurements(data_dir) for m in models]
    write_json_atomic(out / "campaign.json", {"data_dir": str(data_dir), "models": list(models),
                                              "max_evals": max_evals, "seed": seed, "window": window,
                                              "settle": settle, "free": list(free) if free else None,
                                              "tare": tare, "restarts": int(restarts),
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


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="lss campaign", description=__doc__.splitlines()[0])
    ap.add_argument("data_dir")
    ap.add_argument("--models", default="HC,HW,LW,LN")
    ap.add_argument("--out", required=True)
    ap.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler")
    ap.add_argument("--workers", type=int, default=2, help="local processes (without --scheduler)")
    ap.add_argument("--max-evals", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--window", type=float, default=None, help="use only the first seconds of each record")
    ap.add_argument("--settle", type=float, default=4.0, help="simulated settling before the trigger is armed, s")
    ap.add_argument("--free", default=None, help="design variables to identify (default: all ten)")
    ap.add_argument("--restarts", type=int, default=0,
                    help="restart a converged complex around the best point up to N times (0: as published)")
    ap.add_argument("--tare", action="store_true",
                    help="take out zero errors within 3 sigma of the transducer's declared offset")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    from .cli import _free, _model
    models = [_model(m) for m in args.models.split(",") if m.strip()]
    free = _free(args.free) if args.free else None
    results = run_campaign(Path(args.data_dir), models, Path(args.out), workers=args.workers,
                           scheduler=args.scheduler, max_evals=args.max_evals, seed=args.seed,
                           window=args.window, settle=args.settle, free=free, progress=not args.no_progress,
                           tare=args.tare, restarts=args.restarts)
    print(f"{len(results)} identifications in {args.out}/results; `lss report {args.out}` makes the report")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
