"""Identification with workers (the parallel Complex-RFP behind the journal).

On a cheap objective, no FMU: a quadratic bowl in the four CoRs that raises
in one corner of the box, in whichever process evaluates it. With workers the
speculative optimiser evaluates points it then discards; the result's
history must be the optimiser's own (the used evaluations, in the order the
method used them), which is the serial run's history for the same seed. An
exception in a worker must be a bad point with a logged line, and a run with
workers, interrupted, must resume from its journal to the same result without
simulating a journaled point again.
"""
from __future__ import annotations

import json
import logging
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from identification.pipeline.identify import Journal, identify
from identification.objective.problem import DESIGN, IdentificationProblem

CORS = DESIGN[:4]
CENTRE = np.array([0.46, 0.558, 0.351, 0.645])
WEIGHT = np.array([1.0, 3.0, 2.0, 5.0])
BUDGET = 150
SEED = 2


def raises_at(x) -> bool:
    """The corner where the objective raises: about a quarter of the box."""
    return x[0] + x[3] > 1.3


class QuadProblem(IdentificationProblem):
    """An IdentificationProblem whose objective is a bowl; raises in a corner."""

    delay = 0.0  # seconds per evaluation (to interrupt a run in the middle)

    def __call__(self, x) -> float:
        x = np.asarray(x, float)
        if self.delay:
            time.sleep(self.delay)
        if raises_at(x):
            raise RuntimeError(f"boom in process {os.getpid()}")
        return float(np.sum(WEIGHT * (x - CENTRE) ** 2))

    def channel_errors(self, x) -> np.ndarray:
        return np.full(7, math.sqrt(self(x) / 7))


def quad_problem(delay: float = 0.0) -> QuadProblem:
    t = np.arange(10) / 300.0
    p = QuadProblem(np.zeros((len(t), 7)), t, "layout7", "LW", {k: (0.2, 0.9) for k in CORS},
                    free=CORS, x0={k: 0.55 for k in CORS}, name="quad")
    p.delay = delay
    return p


def run(journal=None, workers=2, **kw):
    return identify(quad_problem(), max_evals=BUDGET, seed=SEED, progress=False, journal=journal,
                    workers=workers, **kw)


def journal_keys(path: Path) -> list:
    return [json.loads(ln)["k"] for ln in path.read_text().splitlines()]


def without_round(iterations: dict) -> dict:
    return {k: np.asarray(v) for k, v in iterations.items() if k != "round"}


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    return run(tmp_path_factory.mktemp("serial") / "j.jsonl", workers=1)


@pytest.fixture(scope="module")
def parallel(tmp_path_factory):
    d = tmp_path_factory.mktemp("parallel")
    return run(d / "j.jsonl", workers=2), d / "j.jsonl"


def test_history_is_the_optimisers_own_and_equals_the_serial_run(serial, parallel):
    par, _ = parallel
    opt = par.optimizer
    # the case at stake: speculation evaluated points the method never used
    assert opt.nfev > opt.nfev_used and opt.history.discarded.any()
    used = opt.history.used_order()
    assert np.array_equal(par.history_f, opt.history.f[used])
    assert len(par.history_f) == par.nfev == opt.nfev_used <= BUDGET
    assert par.nfev_total == opt.nfev
    # the same run as serial Complex-RF from the same seed
    assert np.array_equal(par.history_f, serial.history_f)
    assert np.array_equal(par.x, serial.x) and par.f == serial.f and par.f0 == serial.f0
    assert par.nfev == serial.nfev and par.message == serial.message
    for k, v in without_round(serial.iterations).items():
        assert np.array_equal(without_round(par.iterations)[k], v), k
    # the history figure: the best so far ends at the result; f0 is x0's value
    assert np.min(par.history_f) == par.f
    assert par.f0 == quad_problem()(par.x0)
    # every value in the history is the objective at the point the method used (inf: raised)
    for x, f in zip(opt.history.x[used], par.history_f):
        assert f == (math.inf if raises_at(x) else quad_problem()(x))


def test_result_json_with_workers_is_the_serial_one(serial, parallel):
    par, _ = parallel
    d = json.loads(json.dumps(par.to_dict()))
    s = json.loads(json.dumps(serial.to_dict()))
    for key in ("x", "f", "f0", "nfev", "history_f", "message", "x0", "values"):
        assert d[key] == s[key], key
    for k in s["iterations"]:
        if k != "round":
            assert d["iterations"][k] == s["iterations"][k], k
    assert len(d["history_f"]) == d["nfev"]
    assert d["iterations"]["nfev"][-1] == d["nfev"]
    assert d["discarded"] == d["nfev_total"] - d["nfev"] > 0 and s["discarded"] == 0
    assert d["workers"] == 2 and s["workers"] == 1
    assert d["rounds"] < s["rounds"] == s["nfev"]


def test_an_exception_in_a_worker_is_a_bad_point_with_a_logged_line(tmp_path, caplog):
    caplog.set_level(logging.WARNING)
    journal = tmp_path / "j.jsonl"
    res = run(journal, workers=2)  # finishes: no exception escapes
    opt = res.optimizer
    assert opt.n_bad > 0 and len(opt.history.errors) == opt.n_bad
    pids = set()
    for i, msg in opt.history.errors:
        assert raises_at(opt.history.x[i]) and opt.history.bad[i] and opt.history.f[i] == math.inf
        pids.add(int(re.fullmatch(r"RuntimeError: boom in process (\d+)", msg).group(1)))
    assert os.getpid() not in pids  # raised in the workers, not here
    logged = [r.getMessage() for r in caplog.records if "objective failed at evaluation" in r.getMessage()]
    assert len(logged) == opt.n_bad and all("boom in process" in m for m in logged)
    # used bad points are in the history as inf, the best is a real value
    assert np.isinf(res.history_f).sum() == opt.history.bad[opt.history.used_order()].sum() > 0
    assert math.isfinite(res.f) and res.f < 1e-3
    # a raise is not journaled (as in the serial run): it is tried again after a restart
    rows = [json.loads(ln) for ln in journal.read_text().splitlines()]
    assert not any(raises_at(r["x"]) for r in rows)
    assert len(rows) == opt.nfev - opt.n_bad
    assert res.evaluated == opt.nfev


def test_truncated_journal_with_workers_resumes_to_the_same_result(parallel, tmp_path):
    full, full_journal = parallel
    journal = tmp_path / "j.jsonl"
    lines = full_journal.read_text().splitlines()
    keep = 40
    # killed while writing line keep + 1: `keep` whole lines survive, the next is cut
    journal.write_text("\n".join(lines[:keep]) + "\n" + lines[keep][: len(lines[keep]) // 2])
    again = run(journal, workers=2)
    assert np.array_equal(again.x, full.x) and again.f == full.f
    assert np.array_equal(again.history_f, full.history_f) and again.nfev_total == full.nfev_total
    assert again.replayed == keep
    assert again.evaluated == full.evaluated - keep  # nothing journaled is simulated again
    keys = journal_keys(journal)  # every line readable: the cut line was dropped
    assert len(keys) == len(set(keys)) == len(lines)
    # a second restart replays everything
    third = run(journal, workers=2)
    assert third.evaluated == full.optimizer.n_bad  # only the raises, which are never journaled
    assert np.array_equal(third.history_f, full.history_f)


def test_journal_drops_a_cut_last_line(tmp_path):
    path = tmp_path / "j.jsonl"
    jr = Journal(path)
    jr.put(np.array([0.3, 0.4]), 1.5)
    jr.put(np.array([0.5, 0.6]), 2.5)
    jr.close()
    text = path.read_text()
    path.write_text(text[: len(text) - 7])  # the second line cut
    jr = Journal(path)
    assert len(jr.cache) == 1
    jr.put(np.array([0.7, 0.8]), 3.5)
    jr.close()
    assert len(Journal(path).cache) == 2


def _child(journal: str) -> None:
    """A run with workers and slow evaluations, to be killed (see below)."""
    p = quad_problem(delay=0.03)
    identify(p, max_evals=BUDGET, seed=SEED, progress=False, journal=Path(journal), workers=2)


def test_killed_run_with_workers_resumes_from_its_journal(parallel, tmp_path):
    full, _ = parallel
    journal = tmp_path / "j.jsonl"
    here = Path(__file__).resolve().parent
    code = (f"import sys; sys.path[:0] = [{str(here)!r}, {str(here.parent)!r}]; "
            f"from test_identify_parallel import _child; _child({str(journal)!r})")
    proc = subprocess.Popen([sys.executable, "-c", code], start_new_session=True)
    deadline = time.time() + 120
    try:
        while time.time() < deadline and proc.poll() is None:
            if journal.exists() and journal.read_text().count("\n") >= 30:
                os.killpg(proc.pid, signal.SIGKILL)  # the run and its workers
                break
            time.sleep(0.02)
    finally:
        if proc.poll() is None and time.time() >= deadline:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the run ended before it could be killed"
    n_before = len(Journal(journal).cache)
    assert n_before >= 30
    assert n_before < full.nfev_total - full.optimizer.n_bad, "the kill came too late to test a resume"
    again = run(journal, workers=2)
    assert np.array_equal(again.x, full.x) and again.f == full.f
    assert np.array_equal(again.history_f, full.history_f)
    assert again.replayed == n_before
    assert again.evaluated == full.evaluated - n_before  # no evaluation lost or done twice
    keys = journal_keys(journal)
    assert len(keys) == len(set(keys)) == full.nfev_total - full.optimizer.n_bad
