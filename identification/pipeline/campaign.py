"""The campaign: every sorter x every contact model through the front door
(identification.pipeline.driver), in parallel, resumable.

A sorter is the set of records identified together. Records are grouped by
one rule: measurement folders of the same name under the data folders given
are records of one sorter (`lss rig --repeat K` writes the K-th record of a
measurement under the same name in another folder), so

    lss campaign data data_r1 data_r2 --models LW --out DIR

fits each measurement's three records jointly. A manifest file says the
grouping explicitly instead (`--manifest sorters.toml`):

    [sorters]
    line_a = ["site/a/run1", "site/a/run2"]    # paths relative to the file
    line_b = ["site/b/run1"]

Every task is the front door's `identify_records` with one `Settings` (the
defaults, or an expert's TOML) on local processes or an existing Dask
cluster. Results are written atomically as each finishes
(`results/<sorter>_<model>.json`), every evaluation is journaled
(`journals/`); a campaign killed at any moment and started again skips what
is finished and resumes the rest from its journal. A resume with other
settings or another seed is refused: the results would mix two methods.

Two conditions (`surveyed`): on the design drawing (what a user has), or
with each sorter's survey given to the FMU (lss_fmu.survey: its as-built
track, the carts' mass, the guide gap; `DATA/survey/mNN.json` beside each
record, as the rig writes it for the field set), so that a report can show
how much of the law question is a question of the geometry.
"""
from __future__ import annotations

import json
import logging
import re
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence, Union

from lss_fmu.atomic import write_json_atomic
from lss_fmu.design import parse_model
from lss_fmu.measurement import find_measurements, load_measurement
from lss_fmu.survey import SurveyError, load_survey, same_survey, survey_path
from tqdm import tqdm

from .driver import RecordsError, build_problem, check_records, identify_records
from .settings import Settings, read_toml

log = logging.getLogger(__name__)


class CampaignError(ValueError):
    """A campaign that cannot run as asked; names the file, sorter or setting."""


@dataclass(frozen=True)
class Sorter:
    name: str
    records: tuple      # measurement folders, identified jointly


@dataclass(frozen=True)
class Task:
    sorter: Sorter
    model: str
    out: str             # campaign folder
    settings: Settings
    seed: int
    surveyed: bool = False   # the sorter's survey (lss_fmu.survey) given to the FMU

    @property
    def key(self) -> str:
        return f"{self.sorter.name}_{self.model}"

    @property
    def result_path(self) -> Path:
        return Path(self.out) / "results" / f"{self.key}.json"

    @property
    def journal_path(self) -> Path:
        return Path(self.out) / "journals" / f"{self.key}.jsonl"


def sorters_in(data_dirs: Sequence[Union[str, Path]]) -> list:
    """The sorters of `data_dirs`: the measurement folders of one name, one
    from each data folder that has it, in the order the folders are given."""
    groups: dict = {}
    for d in data_dirs:
        found = find_measurements(d)
        if not found:
            raise FileNotFoundError(f"{d} holds no measurement (no meta.json in it or below)")
        names = [p.name for p in found]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise CampaignError(f"{d}: measurement folders share a name ({', '.join(twice[:5])}); records of one "
                                f"sorter are grouped by folder name across data folders, so within one folder "
                                f"each measurement needs its own name")
        for p in found:
            groups.setdefault(p.name, []).append(str(p))
    return [Sorter(name, tuple(paths)) for name, paths in groups.items()]


def sorters_of_manifest(path: Union[str, Path]) -> list:
    """The sorters a manifest's [sorters] table names (paths relative to the file)."""
    path = Path(path)
    table = read_toml(path, CampaignError).get("sorters")
    if not isinstance(table, dict) or not table:
        raise CampaignError(f"{path}: needs a [sorters] table of name = [record folders]")
    out = []
    for name, recs in table.items():
        if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):   # it names the sorter's result and journal files
            raise CampaignError(f"{path}: sorter name {name!r}: use letters, digits, '_', '.' and '-' only")
        if not isinstance(recs, list) or not recs or not all(isinstance(r, str) for r in recs):
            raise CampaignError(f"{path}: sorters.{name} = {recs!r}: must be a list of record folders")
        folders = [(path.parent / r) for r in recs]
        for f in folders:
            if not (f / "meta.json").is_file():
                raise CampaignError(f"{path}: sorters.{name}: {f} is not a measurement folder (no meta.json)")
        out.append(Sorter(str(name), tuple(str(f) for f in folders)))
    return out


def survey_of(sorter: Sorter) -> dict:
    """The FMU values of a sorter's survey: each record's (DATA/survey/mNN.json
    beside it), which must all describe the same sorter."""
    surveys = [(p, load_survey(survey_path(p))) for p in sorter.records]
    first, s0 = surveys[0]
    for p, s in surveys[1:]:
        if not same_survey(s0, s):
            raise CampaignError(f"sorter {sorter.name}: the surveys {survey_path(first)} and {survey_path(p)} "
                                f"differ: records of one sorter have one survey")
    return s0


def run_task(task: Task) -> dict:
    """One sorter identified with one model (in a worker); writes its result file atomically."""
    records = [load_measurement(p) for p in task.sorter.records]
    task.journal_path.parent.mkdir(parents=True, exist_ok=True)
    c0 = time.process_time()
    survey = survey_of(task.sorter) if task.surveyed else None
    problem = build_problem(records, task.model, task.settings, survey=survey)
    try:
        res = identify_records(records, task.model, task.settings, seed=task.seed, journal=task.journal_path,
                               problem=problem, survey=survey)
        out = res.to_dict()
    finally:
        for q in getattr(problem, "parts", [problem]):
            q.sim.close()
    out["cpu_s"] = time.process_time() - c0   # this run's (a resumed one: the rest of it)
    meta = records[0].meta or {}
    out.update({"sorter": task.sorter.name, "wheel_type": meta.get("wheel_type"),
                "coupling_type": meta.get("coupling_type"), "number": meta.get("number"),
                "measurement_dir": task.sorter.records[0]})
    write_json_atomic(task.result_path, out)
    return out


def _same_run(out: Path, settings: Settings, seed: int, surveyed: bool = False) -> None:
    """Refuse to resume a campaign that ran with other settings, another seed
    or the other condition (the design drawing, or the survey)."""
    path = out / "campaign.json"
    if not path.exists():
        return
    before = json.loads(path.read_text())
    now = settings.to_dict()
    for key, value in now.items():
        old = (before.get("settings") or {}).get(key)
        if old != value:
            raise CampaignError(f"{path}: began with {key} = {old!r}, now {value!r}: a campaign resumes with the "
                                f"settings it began with (give another --out for new settings)")
    if before.get("seed") != seed:
        raise CampaignError(f"{path}: began with seed {before.get('seed')!r}, now {seed!r}: a campaign resumes "
                            f"with its seed (give another --out)")
    if bool(before.get("surveyed", False)) != bool(surveyed):
        was = "with the survey" if before.get("surveyed") else "on the design drawing"
        raise CampaignError(f"{path}: began {was}, now {'with' if surveyed else 'without'} --surveyed: a "
                            f"campaign resumes in its condition (give another --out)")


def _one_kind(sorters: list, kinds: dict, by_folder: bool) -> None:
    """A campaign compares contact laws on records of one kind: one set and
    one protocol throughout, and, with records grouped by folder name across
    data folders, as many records for every sorter."""
    if len(kinds) > 1:
        (a, sa), (b, sb) = list(kinds.items())[:2]
        raise CampaignError(f"the data mix records of different kinds: {sa.records[0]} is set {a[0]!r}, "
                            f"protocol {a[1]!r}; {sb.records[0]} is set {b[0]!r}, protocol {b[1]!r}; run them as "
                            f"separate campaigns")
    counts = {len(s.records) for s in sorters}
    if by_folder and len(counts) > 1:
        most = max(counts)
        short = next(s for s in sorters if len(s.records) < most)
        raise CampaignError(f"sorter {short.name} has {len(short.records)} record(s) where others have {most}: "
                            f"a measurement is missing from a data folder ({', '.join(short.records)} found)")


def run_campaign(data_dirs: Sequence[Union[str, Path]], models: Sequence[str], out: Union[str, Path], *,
                 settings: Optional[Settings] = None, manifest: Optional[Union[str, Path]] = None,
                 workers: int = 2, scheduler: Optional[str] = None, client=None, seed: int = 0,
                 progress: bool = True, on_result: Optional[Callable[[dict], None]] = None,
                 surveyed: bool = False) -> list:
    """Run what is not finished yet; return all results (finished before or
    now), in sorter then model order. `data_dirs`: folders of measurements,
    grouped by `sorters_in`; `manifest`: a TOML [sorters] table instead.
    `on_result(result)` is called in this process as each task finishes.
    `surveyed`: each sorter identified with its survey given to the FMU
    (lss_fmu.survey: DATA/survey/mNN.json beside each record; checked for
    every sorter before anything runs), else on the design drawing."""
    if isinstance(data_dirs, (str, Path)):
        data_dirs = [data_dirs]
    settings = settings or Settings()
    models = [parse_model(m) for m in models]
    if not models:
        raise CampaignError("no contact model given")
    if scheduler is None and client is None and int(workers) < 1:
        raise CampaignError(f"workers = {workers}: must be at least 1")
    if manifest is not None and data_dirs:
        raise CampaignError("give data folders or a manifest, not both")
    sorters = sorters_of_manifest(manifest) if manifest is not None else sorters_in(data_dirs)
    if not sorters:
        raise CampaignError("no data folder given")
    kinds = {}
    for s in sorters:   # refused before anything runs: a task would fail alone, after the pool had started
        try:
            records = [load_measurement(p) for p in s.records]
            check_records(records)
        except RecordsError as exc:
            raise CampaignError(f"sorter {s.name}: {exc}") from None
        meta = records[0].meta or {}
        kinds.setdefault((meta.get("set"), records[0].protocol.name), s)
        if surveyed:
            try:
                survey_of(s)
            except SurveyError as exc:
                raise CampaignError(f"sorter {s.name}: {exc}") from None
    _one_kind(sorters, kinds, manifest is None and len(data_dirs) > 1)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _same_run(out, settings, seed, surveyed)
    tasks = [Task(s, m, str(out), settings, int(seed), bool(surveyed)) for s in sorters for m in models]
    write_json_atomic(out / "campaign.json", {
        "data_dirs": [str(d) for d in data_dirs], "manifest": None if manifest is None else str(manifest),
        "models": models, "seed": int(seed), "settings": settings.to_dict(), "surveyed": bool(surveyed),
        "sorters": {s.name: list(s.records) for s in sorters}, "tasks": [t.key for t in tasks]})
    todo = [t for t in tasks if not t.result_path.exists()]
    bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc="campaign", unit="id") if progress else None

    def done(r: dict) -> None:
        if bar:
            bar.update(1)
            bar.set_postfix_str(f"{r['sorter']}/{r['model']} f={r['f']:.3g}")
        if on_result is not None:
            on_result(r)

    try:
        if todo and client is None and scheduler:
            from dask.distributed import Client   # optional: only a campaign on a cluster needs dask
            client = Client(scheduler)
        if todo and client is not None:
            from dask.distributed import as_completed as dask_completed
            futures = [client.submit(run_task, t, key=f"lss-{t.key}-{seed}", pure=False) for t in todo]
            for fut in dask_completed(futures):
                done(fut.result())
        elif todo:
            with ProcessPoolExecutor(max(1, int(workers))) as ex:
                futures = [ex.submit(run_task, t) for t in todo]
                for fut in as_completed(futures):
                    done(fut.result())
    finally:
        if bar:
            bar.close()
    return [json.loads(t.result_path.read_text()) for t in tasks]
